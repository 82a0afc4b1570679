"""Other evaluation harnesses' per-episode results, read with each harness's own reader into one row per episode
plus the columns RoboView's factor, value, context and success default to (`roboview.pipelines.audit --format=NAME`).

- `vla_eval`: vla-eval's recording `recording-<eval-id>.sqlite` or its exported `<benchmark>_aggregate.json`
  (a folder: the ones it holds) — LIBERO-plus, LIBERO-Pro and RoboTwin results map without flags.
- `inspect_robots`: Inspect Robots' JSON `EvalLog`s (a folder: its logs); a scene's metadata names the factor.

docs/audit.md has each harness's field mapping.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from roboview.eval.running.harnesses.base import HarnessTable
from roboview.eval.running.harnesses.inspect_robots_logs import read_inspect_robots
from roboview.eval.running.harnesses.vla_eval_results import read_vla_eval

HARNESSES: dict[str, Callable[[Path], HarnessTable]] = {
    "vla_eval": read_vla_eval,
    "inspect_robots": read_inspect_robots,
}


def load(name: str) -> Callable[[Path], HarnessTable]:
    """The reader of harness `name`; an unknown name raises ValueError listing the known ones."""
    if name not in HARNESSES:
        raise ValueError(f"--format={name!r} is not a harness audit reads; known: {', '.join(HARNESSES)}")
    return HARNESSES[name]
