"""The tasks: each one module that declares everything of its own, plus one registry line.

A task module (`pick_place.py`, `push.py`) holds its context factors (`register_factor(...,
task=<name>)`), its env — a `TaskEnv` subclass with its scene additions, target, context placement,
success test and scripted solution — and its `register_task(Task(...))` line, which names its small
presets' contexts too. The world they share lives below, in `roboview.sim`; the visual factors
in `roboview.variation.factors` apply to every task. Suite presets over the registered tasks
are in `roboview.tasks.presets`.

To add a task, write one such module and add it to BUILTIN_MODULES, or publish it from your own
package under the `roboview.tasks` entry-point group so every worker process registers it too
(docs/extending.md).

    >>> make_env("push").target
    'zone'
"""

from __future__ import annotations

import importlib
import importlib.metadata

from roboview.tasks.base import (
    DEFAULT_MAX_STEPS,
    TASKS,
    Task,
    camera_names,
    load_task,
    make_env,
    register_task,
    resolve,
)
from roboview.tasks.env import TaskEnv
from roboview.tasks.expert import ScriptedExpert
from roboview.variation.factors import DEFAULT_TASK

# Registry lines: imported in this order, the order of the tasks in a suite that names several.
BUILTIN_MODULES = (
    "roboview.tasks.pick_place",
    "roboview.tasks.push",
    "roboview.libero.task",
    "roboview.metaworld.task",
    # Last: it registers its presets beside the others (roboview.tasks.presets, which names every task above).
    "roboview.libero.plus_task",
)
# Third-party tasks: a package lists its task modules under this entry-point group.
ENTRY_POINT_GROUP = "roboview.tasks"
for _module in BUILTIN_MODULES:
    importlib.import_module(_module)
for _entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
    importlib.import_module(_entry.value.split(":")[0])

from roboview.tasks.presets import PRESETS, load_preset, register_preset  # noqa: E402  (after the tasks)

__all__ = [
    "BUILTIN_MODULES",
    "DEFAULT_MAX_STEPS",
    "DEFAULT_TASK",
    "ENTRY_POINT_GROUP",
    "PRESETS",
    "TASKS",
    "ScriptedExpert",
    "Task",
    "TaskEnv",
    "camera_names",
    "load_preset",
    "load_task",
    "make_env",
    "register_preset",
    "register_task",
    "resolve",
]
