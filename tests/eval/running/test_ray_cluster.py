"""A real multi-node Ray cluster on this machine: `ray start --head` plus `ray start --address=…` worker nodes
(separate raylets, each in its own process group so the test can end one as a lost machine would end).

Rows on the cluster equal the local backend's; a worker node lost mid-run costs only its episodes in flight
(re-run once on the surviving node, none duplicated or missing); a lost head stops the evaluator with a clear
message and a fresh cluster resumes the same results folder.
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pandas as pd
import pytest

from benchmarks.cluster import RAY, LocalCluster
from tests.helpers import cli
from tests.helpers.evaluation import evaluate, rows

pytestmark = [
    pytest.mark.slow,
    pytest.mark.schedule_first,  # one test of 1.5 min: never the run's last file (tests/conftest.py, schedule)
    pytest.mark.skipif(not RAY.exists(), reason="Ray's `ray` command is not installed next to this Python"),
]

SPLITS, LIMIT, REPEATS = "color,camera_pose", 3, 2  # 12 episodes: a colour and a camera split
ARGS = [
    "--policy.type=expert",
    f"--benchmark.splits={SPLITS}",
    f"--eval.limit={LIMIT}",
    f"--eval.n_repeats={REPEATS}",
    "--eval.image_size=64",
    "--eval.num_workers=2",
    "--eval.backend=ray",
]


class Cluster(LocalCluster):
    """LocalCluster, skipping the test with the reason where Ray cannot start the nodes here."""

    def __init__(self, tmp: Path, workers: int = 1, head_cpus: int = 1) -> None:
        try:
            super().__init__(workers=workers, cpus=1, head_cpus=head_cpus, scratch=tmp)
        except TimeoutError as exc:
            pytest.skip(str(exc))


@pytest.fixture(scope="module")
def reference(tiny_benchmark, tmp_path_factory) -> pd.DataFrame:
    out = tmp_path_factory.mktemp("local")
    evaluate(tiny_benchmark, out, splits=SPLITS, limit=LIMIT, repeats=REPEATS)
    return rows(out)


def _evaluate(bench: Path, out: Path, cluster: Cluster) -> cli.Run | subprocess.Popen:
    """roboview.pipelines.evaluate on the cluster, started (its output, stdout and stderr together, read at its end)."""
    args = [
        f"--benchmark.path={bench}",
        *ARGS,
        f"--eval.ray_address={cluster.address}",
        f"--output_dir={out}",
    ]
    return cli.start("roboview.pipelines.evaluate", *args, env=cluster.env, merge=True)


def _journal_rows(out: Path) -> int:
    journal = out / "episodes.jsonl"
    return len(journal.read_text().splitlines()) if journal.exists() else 0


def _wait_rows(out: Path, n: int, proc: cli.Run | subprocess.Popen, timeout: float = 300) -> None:
    deadline = time.time() + timeout
    while _journal_rows(out) < n:
        assert proc.poll() is None, proc.communicate()[0][-3000:]
        assert time.time() < deadline, f"fewer than {n} episodes after {timeout} s"
        time.sleep(0.2)


def _ray_record(out: Path) -> dict:
    entries = json.loads((out / "provenance.json").read_text())
    return entries[-1]["ray"]


def test_two_nodes_share_the_work_a_lost_worker_node_costs_its_episodes_in_flight_and_a_lost_head_resumes(
    tiny_benchmark, reference, tmp_path
):
    """One cluster, four runs: an evaluation both nodes share, a build its nodes render, an evaluation whose worker
    node is lost mid-run, then one whose head is lost mid-run, which a fresh cluster resumes."""
    cluster = Cluster(tmp_path, workers=1)
    try:
        proc = _evaluate(tiny_benchmark, tmp_path / "ev", cluster)
        output, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, output[-3000:]
        pd.testing.assert_frame_equal(rows(tmp_path / "ev"), reference)
        record = _ray_record(tmp_path / "ev")
        assert record["address"] == cluster.address and record["lost_actors"] == 0
        assert len(record["nodes"]) == 2 and sum(record["nodes"].values()) == len(reference)
        assert min(record["nodes"].values()) >= 2, record  # both nodes ran episodes
        # The build on the same cluster: its nodes render the instances, and the manifest is the local build's.
        build = ["--preset=tiny", "--image_size=64", f"--ray_address={cluster.address}", "--num_workers=2"]
        proc = cli.run(
            "roboview.pipelines.build_benchmark",
            *build,
            f"--output_dir={tmp_path / 'built'}",
            env=cluster.env,
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        version = json.loads((tmp_path / "built" / "benchmark.json").read_text())["benchmark_version"]
        assert version == json.loads((tiny_benchmark / "benchmark.json").read_text())["benchmark_version"]
        # The worker node lost once 3 episodes are written: only its episodes in flight run again, on the head.
        out = tmp_path / "lost"
        proc = _evaluate(tiny_benchmark, out, cluster)
        _wait_rows(out, 3, proc)
        Cluster.kill(cluster.workers[0])
        output, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, output[-3000:]
        # Then the head lost once 3 episodes of another run are written: the evaluator stops and says so.
        resumed = tmp_path / "head"
        proc = _evaluate(tiny_benchmark, resumed, cluster)
        _wait_rows(resumed, 3, proc)
        Cluster.kill(cluster.head)
        stopped, _ = proc.communicate(timeout=180)
    finally:
        cluster.close()
    journal = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    keys = [(r["instance_id"], r["repeat"]) for r in journal]
    assert len(keys) == len(set(keys)) == len(reference)  # nothing duplicated, nothing lost
    pd.testing.assert_frame_equal(rows(out), reference)
    record = _ray_record(out)
    assert 1 <= record["lost_actors"] <= 2, record  # the episode(s) in flight on the lost node, re-run once
    # A fresh cluster resumes the stopped run: only the episodes it had not written run.
    assert proc.returncode != 0
    assert "stopped answering" in stopped and "rerun the same command" in stopped, stopped[-3000:]
    written = _journal_rows(resumed)
    assert 3 <= written < len(reference)
    fresh = Cluster(tmp_path, workers=0, head_cpus=2)  # a fresh head alone, with the cores of both nodes
    try:
        proc = _evaluate(tiny_benchmark, resumed, fresh)
        output, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, output[-3000:]
    finally:
        fresh.close()
    assert f"({len(reference) - written} new" in output
    pd.testing.assert_frame_equal(rows(resumed), reference)
