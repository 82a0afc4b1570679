"""The analyses particular to a task (`Task.analyses`), run on one policy's episodes beside the splits' statistics:
each task's declared modules compute their part of metrics.json's `analyses` (LIBERO-plus's camera decomposition,
roboview.libero.decomposition, is one)."""

from __future__ import annotations

from typing import Any

import pandas as pd


def task_analyses(episodes: pd.DataFrame) -> dict[str, Any]:
    """The analyses the episodes' tasks declare (`Task.analyses`), each under its KEY (those with nothing to say
    are left out)."""
    import importlib

    from roboview.tasks import load_task

    out: dict[str, Any] = {}
    for task in episodes["task"].dropna().astype(str).unique() if "task" in episodes else ():
        for name in load_task(task).analyses:
            module = importlib.import_module(name)
            result = module.compute(episodes[episodes["task"].astype(str) == task])
            if result is not None:
                out[module.KEY] = result
    return out
