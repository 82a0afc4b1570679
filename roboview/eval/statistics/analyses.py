"""The analyses particular to a task (`Task.analyses`), run on one policy's episodes beside the splits' statistics:
each task's declared designs computed into metrics.json's `analyses` (a factor decomposition,
roboview.eval.statistics.decompose; LIBERO-plus's camera dimension is one)."""

from __future__ import annotations

from typing import Any

import pandas as pd

from roboview.eval.statistics.decompose import compute


def task_analyses(episodes: pd.DataFrame) -> dict[str, Any]:
    """The analyses the episodes' tasks declare (`Task.analyses`), each under its key (those with nothing to say
    are left out)."""
    from roboview.tasks import load_task

    out: dict[str, Any] = {}
    for task in episodes["task"].dropna().astype(str).unique() if "task" in episodes else ():
        for design in load_task(task).analyses:
            result = compute(episodes[episodes["task"].astype(str) == task], design)
            if result is not None:
                out[design.key] = result
    return out
