"""A CPU policy's actions depend on torch's intra-op threads (its reductions split by thread), enough to change an
episode's steps: run.json records the count the episodes ran with, a resume keeps it, and a replay computes with it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from roboview.eval.running import provenance
from roboview.eval.running.results import RUN_FILE, ResultsError, recorded_threads
from roboview.eval.verification.replay import Replayer
from roboview.eval.verification.results import read_table
from tests.helpers.evaluation import evaluate

pytestmark = pytest.mark.slow


def test_run_json_records_the_threads_and_a_resume_keeps_them(tiny_benchmark, tmp_path):
    out = tmp_path / "run"
    evaluate(tiny_benchmark, out, splits="color", limit=1, workers=1, torch_threads=3)
    assert json.loads((out / RUN_FILE).read_text())["torch_threads"] == 3
    # Resumed without the flag (whatever the load average now says): the folder's own count, not a new fit.
    evaluate(tiny_benchmark, out, splits="color", limit=1, repeats=2, workers=1)
    assert json.loads((out / RUN_FILE).read_text())["torch_threads"] == 3
    assert [e["torch_threads"]["per_worker"] for e in provenance.read(out)] == [3, 3]
    # Asked for another count explicitly: refused, naming it, before any episode.
    with pytest.raises(ResultsError, match=r"torch_threads: existing 3 vs requested 2"):
        evaluate(tiny_benchmark, out, splits="color", limit=1, repeats=2, workers=1, torch_threads=2)
    assert recorded_threads(out) == 3


def test_a_replay_computes_with_the_recorded_threads(tiny_benchmark, tmp_path):
    out = tmp_path / "run"
    evaluate(tiny_benchmark, out, splits="color", limit=1, workers=1, torch_threads=3)
    _, run = read_table(out)
    replayer = Replayer()
    try:
        worker = replayer.worker(run, replayer.policy(run), "pick_place")
        assert worker.spec.torch_threads == 3
        # Another count is another worker: a board's bundles of one policy at other counts never share one.
        other = replayer.worker(run | {"torch_threads": 1}, replayer.policy(run), "pick_place")
        assert other is not worker and other.spec.torch_threads == 1
    finally:
        replayer.close()


def test_a_folder_written_before_run_json_recorded_threads(tmp_path):
    """Its provenance entries say what each part of the run used: one count when they agree, none when not."""
    folder = tmp_path / "old"
    folder.mkdir()
    (folder / RUN_FILE).write_text(json.dumps({"policy": "lerobot"}))
    entry = {
        "started": "2026-01-01T00:00:00+00:00",
        "torch_threads": {"per_worker": 1, "load_average_1m": 0.4},
    }
    provenance.write(folder, [entry, entry])
    assert recorded_threads(folder) == 1
    provenance.write(folder, [entry, {**entry, "torch_threads": {"per_worker": 2}}])
    assert recorded_threads(folder) is None
    provenance.write(folder, [{"started": "2026-01-01T00:00:00+00:00"}])  # older still: nothing recorded
    assert recorded_threads(folder) is None
    (folder / RUN_FILE).write_text(json.dumps({"policy": "lerobot", "torch_threads": 4}))
    assert recorded_threads(Path(folder)) == 4
