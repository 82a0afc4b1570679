"""The tasks: the registries of tasks, worlds and suite presets, and the contract every world's wing builds on.

A task module (`pick_place.py`, `push.py`) holds its context factors (`register_factor(...,
task=<name>)`), its env — a `TaskEnv` subclass with its scene additions, target, context placement,
success test and scripted solution — and its `register_task(Task(...))` line, which names its small
presets' contexts too. The world they share lives below, in `roboview.sim`; the visual factors
in `roboview.variation.factors` apply to every task. RoboView's own suite presets are in
`roboview.tasks.presets`; LIBERO's, Meta-World's and LIBERO-plus's in their wings.

Nothing here imports a task module or a wing. Each registering module is named under the `roboview.tasks`
entry-point group (RoboView's own in its pyproject.toml; a task of your own package in that package's, so every
worker process registers it too: docs/extending.md), and the registries import them all when first read
(`discover`, roboview.core.registry): `load_task`, `load_preset`, `load_world`, and any read of `TASKS`, `PRESETS`,
`WORLDS` or the factor registry. A task's gymnasium id is registered with it.

    >>> make_env("push").target
    'zone'
"""

from __future__ import annotations

from roboview.core.registry import ENTRY_POINT_GROUP, discover, wing_modules
from roboview.tasks.base import (
    DEFAULT_MAX_STEPS,
    PRESETS,
    TASKS,
    Task,
    camera_names,
    load_preset,
    load_task,
    make_env,
    register_preset,
    register_task,
    resolve,
)
from roboview.tasks.env import TaskEnv
from roboview.tasks.expert import ScriptedExpert
from roboview.variation.factors import DEFAULT_TASK

__all__ = [
    "DEFAULT_MAX_STEPS",
    "DEFAULT_TASK",
    "ENTRY_POINT_GROUP",
    "PRESETS",
    "TASKS",
    "ScriptedExpert",
    "Task",
    "TaskEnv",
    "camera_names",
    "discover",
    "load_preset",
    "load_task",
    "make_env",
    "register_preset",
    "register_task",
    "resolve",
    "wing_modules",
]
