"""`--dataset.cover_contexts`: attempts run the listed context values' combinations in turn, each once per cycle."""

from __future__ import annotations

from collections import Counter

import pytest

from roboview.demos.recorder import attempt_contexts
from roboview.pipelines.collect import DatasetConfig

pytestmark = pytest.mark.fast

TASKS = tuple(f"libero_object/{i}" for i in range(10))
INITS = tuple(str(s) for s in range(10, 50))


def test_attempts_cover_every_combination_once_per_cycle():
    contexts = {"libero_task": TASKS, "init_state": INITS}
    runs = [attempt_contexts(contexts, a, cover=True) for a in range(400)]
    assert all(len(v) == 1 for run in runs for v in run.values())
    pairs = Counter((run["libero_task"][0], run["init_state"][0]) for run in runs)
    assert len(pairs) == 400 and set(pairs.values()) == {1}
    assert Counter(p[0] for p in pairs) == dict.fromkeys(TASKS, 40)
    # In the order listed, cycling: the last factor varies fastest, attempt 400 is attempt 0 again.
    assert runs[0] == {"libero_task": (TASKS[0],), "init_state": ("10",)}
    assert runs[41] == {"libero_task": (TASKS[1],), "init_state": ("11",)}
    assert attempt_contexts(contexts, 400, cover=True) == runs[0]


def test_without_cover_every_attempt_draws_among_all_values():
    contexts = {"libero_task": TASKS}
    assert attempt_contexts(contexts, 7, cover=False) is contexts
    assert attempt_contexts({}, 7, cover=True) == {}


def test_cover_without_contexts_is_refused_naming_the_flags(tmp_path):
    with pytest.raises(ValueError, match=r"--dataset.cover_contexts=true needs --dataset.contexts"):
        DatasetConfig(repo_id="roboview/x", root=str(tmp_path / "d"), task="pick_place", cover_contexts=True)
