"""Other evaluation harnesses' per-episode results, read with each harness's own reader into one row per episode
plus the columns RoboView's factor, value, context and success default to (`roboview.pipelines.audit --format=NAME`).

- `vla_eval`: vla-eval's recording `recording-<eval-id>.sqlite` or its exported `<benchmark>_aggregate.json`
  (a folder: the ones it holds) — LIBERO-plus, LIBERO-Pro and RoboTwin results map without flags.
- `inspect_robots`: Inspect Robots' JSON `EvalLog`s (a folder: its logs); a scene's metadata names the factor.
- `gauntlet`: gauntlet-robotics' `episodes.json` (a run's `--out` folder); its perturbation axes are the factor.
- `xevals`: xevals' `run.json` (a run folder); a cell's perturbation is the factor, its severity the value.

docs/audit.md has each harness's field mapping. Another harness's reader is added from its own package under the
`roboview.harnesses` entry-point group: `name = "module:reader"`, a callable `reader(path) -> HarnessTable`
(docs/extending.md).
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Callable
from pathlib import Path

from roboview.eval.running.harnesses.base import HarnessTable
from roboview.eval.running.harnesses.gauntlet_episodes import read_gauntlet
from roboview.eval.running.harnesses.inspect_robots_logs import read_inspect_robots
from roboview.eval.running.harnesses.vla_eval_results import read_vla_eval
from roboview.eval.running.harnesses.xevals_runs import read_xevals

HARNESSES: dict[str, Callable[[Path], HarnessTable]] = {
    "vla_eval": read_vla_eval,
    "inspect_robots": read_inspect_robots,
    "gauntlet": read_gauntlet,
    "xevals": read_xevals,
}


# Third-party packages add readers through entry points in this group: `name = "module:reader"`.
ENTRY_POINT_GROUP = "roboview.harnesses"


def harness_names() -> tuple[str, ...]:
    """The builtin harnesses and every `roboview.harnesses` entry point."""
    return (*HARNESSES, *(e.name for e in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)))


def load(name: str) -> Callable[[Path], HarnessTable]:
    """The reader of harness `name` (builtin, else a `roboview.harnesses` entry point); an unknown name raises
    ValueError listing the known ones."""
    for entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP, name=name):
        if name not in HARNESSES:
            return entry.load()
    if name not in HARNESSES:
        raise ValueError(
            f"--format={name!r} is not a harness audit reads; known: {', '.join(harness_names())}"
        )
    return HARNESSES[name]
