"""evaluate on the tiny benchmark: expert per split, resume, local vs Ray, Rerun, LeRobot adapter, bad input."""

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
from roboview.policies.base import PolicyConfig
from roboview.policies.types import policy_config
from tests.helpers import cli
from tests.helpers.evaluation import evaluate, rows

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
RERUN = Path(sys.executable).parent / "rerun"


@pytest.fixture(scope="module")
def bench(tiny_benchmark) -> Path:
    return tiny_benchmark


def test_expert_succeeds_on_a_sample_of_every_split(bench, tmp_path):
    result = evaluate(bench, tmp_path / "ev", limit=2, repeats=1)
    df = pd.read_parquet(tmp_path / "ev" / "episodes.parquet")
    assert set(df["split"]) == {"color", "camera_pose", "camera_euler", "dist_scale", "color_x_camera_pose"}
    assert len(df) == 10 and result.new_episodes == 10
    for split, sr in df.groupby("split")["success"].mean().items():
        assert sr >= 0.95, f"expert SR {sr:.0%} on {split}"
    assert (df["policy"] == "expert").all() and (df["failure_reason"] == "").all()
    # Episode seeds follow the documented derivation (docs/formats.md, "Identity and seeds").
    from roboview.variation.instances import episode_seed

    assert all(episode_seed(c, r) == s for c, r, s in zip(df["context_id"], df["repeat"], df["episode_seed"]))


def test_interrupted_run_resumes_without_duplicates_or_gaps(bench, tmp_path):
    ref = tmp_path / "ref"
    evaluate(bench, ref, splits="color,dist_scale", limit=2, repeats=2)
    out = tmp_path / "killed"
    proc = cli.start(
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        "--policy.type=expert",
        "--benchmark.splits=color,dist_scale",
        "--eval.limit=2",
        "--eval.n_repeats=2",
        "--eval.image_size=64",
        f"--output_dir={out}",
        new_session=True,
    )
    journal = out / "episodes.jsonl"
    deadline = time.time() + 300
    while time.time() < deadline and not (journal.exists() and len(journal.read_text().splitlines()) >= 3):
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = len(journal.read_text().splitlines())
    assert 3 <= done_before < 8
    with journal.open("a") as f:
        f.write('{"instance_id": "torn')  # a line cut by the kill
    result = evaluate(bench, out, splits="color,dist_scale", limit=2, repeats=2)
    assert result.new_episodes == 8 - done_before
    got, want = rows(out), rows(ref)
    assert not got.duplicated(["instance_id", "repeat"]).any() and len(got) == 8
    pd.testing.assert_frame_equal(got, want)
    assert evaluate(bench, out, splits="color,dist_scale", limit=2, repeats=2).new_episodes == 0


def test_end_effector_control_runs_and_is_recorded(bench, tmp_path):
    """`--policy.control=ee_delta`: envs made in it, the expert succeeds through it, run.json and provenance record
    it, and a resume asking for another control is refused."""
    from roboview.eval.running import provenance
    from roboview.eval.running.results import ResultsError

    out = tmp_path / "ee"
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), "color"),
        policy_config("expert", control="ee_delta"),
        EvalConfig(n_repeats=1, limit=2, num_workers=1, image_size=64, torch_threads=2),
        str(out),
    )
    result = run(cfg)
    assert result.new_episodes == 2 and rows(out)["success"].all()
    assert provenance.read(out)[-1]["torch_threads"]["per_worker"] == 2
    assert json.loads((out / "run.json").read_text())["control"] == "ee_delta"
    assert provenance.read(out)[-1]["control"] == "ee_delta"
    with pytest.raises(ResultsError, match="control: existing 'ee_delta' vs requested 'joint'"):
        evaluate(bench, out, splits="color", limit=2, workers=1)


def test_more_repeats_extend_a_run_in_rounds_and_fewer_are_refused(bench, tmp_path):
    """Evaluating in rounds (`--eval.n_repeats=1`, then 2, …, as roboview-compare's loop does): each call keeps the
    rows written and runs only the new repeat; asking for fewer repeats than the folder holds is a different run."""
    from roboview.eval.running.results import ResultsError

    out = tmp_path / "rounds"
    first = evaluate(bench, out, splits="color", limit=2, repeats=1, workers=1, max_steps=4)
    second = evaluate(bench, out, splits="color", limit=2, repeats=2, workers=1, max_steps=4)
    assert (first.new_episodes, second.new_episodes) == (2, 2)
    assert sorted(rows(out)["repeat"]) == [0, 0, 1, 1]
    assert json.loads((out / "run.json").read_text())["n_repeats"] == {"color": 2}
    with pytest.raises(ResultsError, match="n_repeats: existing"):
        evaluate(bench, out, splits="color", limit=2, repeats=1, workers=1, max_steps=4)


def test_local_and_ray_backends_agree_row_for_row(bench, tmp_path, monkeypatch):
    evaluate(bench, tmp_path / "local", splits="color,camera_pose", limit=1, repeats=2)
    # A home without a Ray token: the local instance authenticates with a private one and writes none there.
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    for name in ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH"):
        monkeypatch.delenv(name, raising=False)
    evaluate(bench, tmp_path / "ray", splits="color,camera_pose", limit=1, repeats=2, backend="ray")
    import ray

    ray.shutdown()
    token = Path(os.environ.pop("RAY_AUTH_TOKEN_PATH"))
    assert len(token.read_text()) == 64 and not str(token).startswith(str(tmp_path / "home"))
    assert not (tmp_path / "home" / ".ray").exists()
    local, remote = rows(tmp_path / "local"), rows(tmp_path / "ray")
    assert len(local) == 4
    pd.testing.assert_frame_equal(local, remote)


def test_rerun_recording_verifies(bench, tmp_path):
    rrd = tmp_path / "eval.rrd"
    evaluate(bench, tmp_path / "ev", splits="color", limit=2, repeats=1, rerun=str(rrd))
    proc = subprocess.run(
        [str(RERUN), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert "verified without error" in proc.stdout + proc.stderr
    # Read back with rerun's own reader: every episode's entities, one camera frame per logged step.
    import rerun as rr
    from rerun.experimental import RrdReader

    steps: dict[str, list[int]] = {}
    entities = set()
    for chunk in RrdReader(rrd).stream():
        entities.add(chunk.entity_path)
        if "/camera/" in chunk.entity_path and not chunk.is_static:
            steps.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().column("step").to_pylist())
    df = pd.read_parquet(tmp_path / "ev" / "episodes.parquet")
    assert len(df) == 2
    expected = {}
    for row in df.itertuples():
        # The reader prints entity paths escaped ("color\\=red"), as rerun.new_entity_path builds them.
        base = rr.new_entity_path(
            ["episodes", "color", f"color={row.value}", row.instance_id, f"r{row.repeat}"]
        )
        leaves = ("instance", "ee", "object", "ee_path", "object_path", "outcome")
        assert {f"{base}/{leaf}" for leaf in leaves} <= entities, sorted(entities)
        cams = sorted(e.rpartition("/")[2] for e in steps if e.startswith(f"{base}/camera/"))
        assert cams, f"no camera frames under {base}"
        # One JPEG per step on the `step` timeline: the observation each action was chosen from.
        expected |= {f"{base}/camera/{cam}": list(range(row.steps)) for cam in cams}
    assert {entity: sorted(found) for entity, found in steps.items()} == expected
    assert "/summary/color/sr_by_value" in entities and "/summary/color/values" in entities


def test_lerobot_adapter_runs_a_two_step_checkpoint(bench, tiny_checkpoint, tmp_path):
    # No image size given: the env renders the checkpoint's own 64² (its cameras: left_top + wrist).
    result = evaluate(
        bench,
        tmp_path / "ev",
        policy="lerobot",
        path=str(tiny_checkpoint),
        splits="color",
        limit=1,
        repeats=1,
        workers=1,
        max_steps=8,
        image_size=0,
    )
    assert json.loads((tmp_path / "ev" / "run.json").read_text())["image_size"] == 64
    df = pd.read_parquet(tmp_path / "ev" / "episodes.parquet")
    assert result.episodes == 1 and df["policy"].tolist() == ["lerobot:act"]
    assert df["steps"].tolist() == [8] and not df["success"].any()
    assert "within 8 steps" in df["failure_reason"][0]


def _cli(*args: str) -> subprocess.CompletedProcess:
    """roboview.pipelines.evaluate with `args` (the expert unless they name a --policy.type: there is no default)."""
    if not any(a.startswith("--policy.type=") for a in args):
        args = ("--policy.type=expert", *args)
    return cli.run("roboview.pipelines.evaluate", *args, timeout=300)


def _main(capsys, *args: str) -> subprocess.CompletedProcess:
    """`_cli(*args)` through roboview.pipelines.evaluate's `main` in this process: its exit status and stderr."""
    from roboview.pipelines.evaluate import main

    if not any(a.startswith("--policy.type=") for a in args):
        args = ("--policy.type=expert", *args)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    return subprocess.CompletedProcess(args, exit_.value.code, "", capsys.readouterr().err)


def test_bad_input_fails_before_any_rollout(bench, tiny_checkpoint, tmp_path, capsys):
    out = tmp_path / "out"
    # The command line itself (exit status 2, the message on stderr); the rest through the same `main`.
    proc = _cli(f"--benchmark.path={bench}", "--policy.type=oracle", f"--output_dir={out}")
    assert (
        proc.returncode == 2
        and "unknown policy type 'oracle'; allowed: expert, lerobot, lerobot_async, openpi, random"
        in proc.stderr
    )
    proc = _main(capsys, f"--benchmark.path={bench}", "--benchmark.splits=colour", f"--output_dir={out}")
    assert proc.returncode == 2 and "unknown split(s) ['colour']" in proc.stderr
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
        f"--policy.path={tmp_path}",
        f"--output_dir={out}",
    )
    assert proc.returncode == 2 and "holds no LeRobot checkpoint" in proc.stderr
    bad = tmp_path / "bad_ckpt"
    bad.mkdir()
    config = json.loads((tiny_checkpoint / "config.json").read_text())
    config["input_features"]["observation.images.top_down"] = config["input_features"].pop(
        "observation.images.wrist"
    )
    (bad / "config.json").write_text(json.dumps(config))
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
        f"--policy.path={bad}",
        f"--output_dir={out}",
    )
    assert proc.returncode == 2 and "camera 'top_down'" in proc.stderr
    assert not out.exists()
    # Images the env cannot render (non-square): refused before any rollout, naming the shapes.
    config = json.loads((tiny_checkpoint / "config.json").read_text())
    config["input_features"]["observation.images.wrist"]["shape"] = [3, 64, 48]
    (bad / "config.json").write_text(json.dumps(config))
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
        f"--policy.path={bad}",
        f"--output_dir={out}",
    )
    assert proc.returncode == 2 and "(3, 64, 48)" in proc.stderr and "square" in proc.stderr
    assert not out.exists()
    # An explicit image size that disagrees with the checkpoint's: both sizes named, nothing run.
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
        f"--policy.path={tiny_checkpoint}",
        "--eval.image_size=96",
        f"--output_dir={out}",
    )
    assert proc.returncode == 2 and "--eval.image_size=96" in proc.stderr and "64×64" in proc.stderr
    assert not out.exists()
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
        f"--policy.path={tiny_checkpoint}",
        "--policy.device=tpu",
        f"--output_dir={out}",
    )
    assert (
        proc.returncode == 2 and "--policy.device='tpu'" in proc.stderr and "auto, cpu, cuda" in proc.stderr
    )
    # Results from another benchmark version in the output folder: refuse to mix them.
    out.mkdir()
    (out / "run.json").write_text(
        json.dumps({"benchmark_version": "paper-000000000000", "policy": "expert", "results_format": 2})
    )
    proc = _main(
        capsys, f"--benchmark.path={bench}", f"--output_dir={out}", "--eval.limit=1", "--eval.n_repeats=1"
    )
    assert proc.returncode == 2 and "existing 'paper-000000000000' vs requested 'tiny-" in proc.stderr
    assert not (out / "episodes.jsonl").exists()
    # Results written under the old seed rule (no results_format): refuse to resume into them.
    (out / "run.json").write_text(json.dumps({"benchmark_version": "paper-000000000000", "policy": "expert"}))
    proc = _main(
        capsys, f"--benchmark.path={bench}", f"--output_dir={out}", "--eval.limit=1", "--eval.n_repeats=1"
    )
    assert (
        proc.returncode == 2 and "results of format 1" in proc.stderr and "choose a new folder" in proc.stderr
    )
    # Per-split repeats: a typo fails before any rollout, naming the entry.
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        f"--output_dir={tmp_path / 'z'}",
        "--eval.split_repeats=color=two",
    )
    assert proc.returncode == 2 and "'color=two' must be split=N" in proc.stderr
    proc = _main(
        capsys,
        f"--benchmark.path={bench}",
        f"--output_dir={tmp_path / 'v'}",
        "--benchmark.splits=color",
        "--benchmark.values=red,chartreuse",
    )
    assert proc.returncode == 2 and "['chartreuse']" in proc.stderr and "red" in proc.stderr


def test_repeats_per_split_and_the_benchmarks_protocols():
    from roboview.benchmark.protocols import choose, default_protocols

    protocols = default_protocols(["color", "camera_pose", "color_x_camera_pose"], "tiny")
    assert list(protocols) == ["paper", "adaptive", "quick"]
    paper = EvalConfig(protocol="paper")
    paper.follow(protocols["paper"])
    assert (paper.repeats_for("color"), paper.repeats_for("color_x_camera_pose")) == (5, 10)
    quick = EvalConfig(protocol="quick")
    quick.follow(protocols["quick"])
    assert [quick.repeats_for(s) for s in ("color", "color_x_camera_pose")] == [3, 3]
    adaptive = EvalConfig(protocol="adaptive")
    adaptive.follow(protocols["adaptive"])
    assert (
        adaptive.adaptive and adaptive.max_repeats == 10 and adaptive.repeats_for("color_x_camera_pose") == 10
    )
    mixed = EvalConfig(n_repeats=3, split_repeats="color=2, camera_pose=6")
    assert [mixed.repeats_for(s) for s in ("color", "camera_pose", "dist_scale")] == [2, 6, 3]
    with pytest.raises(ValueError, match="drop --eval.n_repeats=3, --eval.limit=4"):
        EvalConfig(protocol="paper", n_repeats=3, limit=4).follow(protocols["paper"])
    with pytest.raises(
        ValueError, match="'pi0' is not a protocol of this benchmark; it declares: paper: 3 splits"
    ):
        choose(protocols, "pi0")


def test_values_filter_keeps_that_value_in_every_context(bench, tmp_path):
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), "color", "red"),
        policy_config("expert"),
        EvalConfig(n_repeats=1, num_workers=1, image_size=64),
        str(tmp_path / "ev"),
    )
    run(cfg)
    df = rows(tmp_path / "ev")
    assert set(df["value"]) == {"red"} and df["context_id"].nunique() == 3 and df["success"].all()


def test_contexts_sample_keeps_every_value_and_the_policy_name_labels_rows(bench, tmp_path):
    from roboview.benchmark.format import load_benchmark

    full = load_benchmark(bench, ["camera_pose", "dist_scale"]).splits
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), "camera_pose,dist_scale"),
        policy_config("random", name="coin"),
        EvalConfig(n_repeats=1, contexts=2, num_workers=1, image_size=64, max_steps=2),
        str(tmp_path / "ev"),
    )
    run(cfg)
    df = rows(tmp_path / "ev")
    assert set(df["policy"]) == {"coin"}
    assert json.loads((tmp_path / "ev" / "run.json").read_text())["policy_name"] == "coin"
    for split, items in full.items():
        first_two = list(dict.fromkeys(i.record["context_id"] for i in items))[:2]
        sub = df[df["split"] == split]
        assert set(sub["context_id"]) == set(first_two)  # the first two contexts of the split...
        assert set(sub["value"]) == {i.record["value"] for i in items}  # ...with every value of it
        assert len(sub) == 2 * len({i.record["value"] for i in items})
    with pytest.raises(ValueError, match="--eval.contexts=-1 must be ≥ 0"):
        EvalConfig(contexts=-1)


def _descendants(pid: int) -> set[int]:
    """Every process under `pid`: its fork server and the workers that server forked, among others."""
    import psutil

    try:
        return {p.pid for p in psutil.Process(pid).children(recursive=True)}
    except psutil.NoSuchProcess:
        return set()


def _alive(pid: int) -> bool:
    state = subprocess.run(
        ["ps", "-o", "stat=", "-p", str(pid)], capture_output=True, text=True
    ).stdout.strip()
    return bool(state) and not state.startswith("Z")


def test_workers_exit_when_the_parent_is_killed(bench, tmp_path):
    # A SIGKILLed evaluation used to leave its spawned workers (≈ 640 MB each) idle for good.
    proc = cli.start(
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        "--policy.type=expert",
        "--eval.image_size=64",
        "--eval.num_workers=2",
        f"--output_dir={tmp_path / 'ev'}",
        new_session=True,
    )
    workers: set[int] = set()
    try:
        deadline = time.time() + 120
        journal = tmp_path / "ev" / "episodes.jsonl"
        while time.time() < deadline and not (journal.exists() and journal.stat().st_size):
            time.sleep(0.5)  # an episode finished: the workers are up
        workers = _descendants(proc.pid)
        assert len(workers) >= 3, "the pool never started"  # its fork server and two workers
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.time() + 30
        while time.time() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.5)
        assert not [w for w in workers if _alive(w)], "workers outlived their parent"
    finally:
        for w in workers | (_descendants(proc.pid) if proc.poll() is None else set()):
            if _alive(w):
                os.kill(w, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()


def test_a_worker_whose_parent_died_while_it_started_exits(tmp_path):
    # A worker still importing its factory's module when its parent is killed must notice too: the parent's pid
    # travels with it, so the worker does not take its adopter for its parent.
    (tmp_path / "slow_factory.py").write_text("import time\ntime.sleep(3)\n\nclass Idle:\n    pass\n")
    pids = tmp_path / "workers.pid"
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import multiprocessing as mp, sys, time\n"
            "from roboview.core.workers import WorkerPool\n"
            "if __name__ == '__main__':\n"
            "    import slow_factory\n"
            "    pool = WorkerPool(1, slow_factory.Idle, method='__eq__')\n"
            "    pool.submit(0)\n"
            f"    open({str(pids)!r}, 'w').write(' '.join(str(p.pid) for p in mp.active_children()))\n"
            "    time.sleep(60)\n",
        ],
        env=os.environ | {"PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])},
        start_new_session=True,
    )
    workers: list[int] = []
    try:
        deadline = time.time() + 60
        while time.time() < deadline and not (pids.exists() and pids.read_text()):
            time.sleep(0.1)
        workers = [int(p) for p in pids.read_text().split()]
        assert workers, "the pool never started"
        parent.kill()  # the worker is still importing slow_factory
        parent.wait()
        deadline = time.time() + 30
        while time.time() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.2)
        assert not [w for w in workers if _alive(w)], "a worker orphaned while starting lingers"
    finally:
        if parent.poll() is None:
            parent.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


class _Flaky:
    """Raises `errors` (one per call, None = answer) from select_action, then holds the arm still."""

    name = "flaky"

    def __init__(self, errors):
        self.errors, self.calls = list(errors), 0

    def reset(self, episode) -> None:
        pass

    def select_action(self, observation):
        self.calls += 1
        error = self.errors.pop(0) if self.errors else None
        if error == "nan":
            return np.full(8, np.nan, dtype=np.float32)
        if error is not None:
            raise error
        return np.append(observation["observation.state"][:7], 0.0).astype(np.float32)


@pytest.mark.parametrize(
    "errors, steps, calls, reason",
    [
        (
            [None, RuntimeError("bad checkpoint output")],
            1,
            2,
            "policy error: RuntimeError: bad checkpoint output",
        ),
        ([TimeoutError("slow"), TimeoutError("slow"), None], 4, 6, "within 4 steps"),  # retried, then fine
        ([ConnectionError("down")] * 3, 0, 3, "policy error after 2 retries: ConnectionError: down"),
        ([None, None, "nan"], 2, 3, "policy error: action of shape (8,)"),
    ],
)
def test_a_policy_that_raises_becomes_a_failed_episode(bench, monkeypatch, errors, steps, calls, reason):
    import roboview.eval.running.rollout as rollout
    from roboview.benchmark.format import load_benchmark

    monkeypatch.setattr(rollout, "RETRY_BACKOFF_S", 0.0)
    policy = _Flaky(errors)

    @dataclass
    class FlakyConfig(PolicyConfig):  # a policy type added by a test: one config class, one registry line
        def build(self, env):
            return policy

    monkeypatch.setitem(PolicyConfig.get_known_choices(), "flaky", FlakyConfig)
    assert policy_config("flaky").type == "flaky"
    worker = rollout.EvalWorker(rollout.WorkerSpec(FlakyConfig(), image_size=32, max_steps=4))
    item = load_benchmark(bench, ["color"]).splits["color"][0]
    row = worker.run(rollout.WorkItem(item, 0)).row
    worker.close()
    assert not row["success"] and row["steps"] == steps and reason in row["failure_reason"]
    assert policy.calls == calls  # every retry is a real call


# -- lazy rendering, batched inference, videos, provenance, lerobot-eval --------- ------------------------------


def test_lazy_observations_are_the_eager_pixels_and_render_only_what_is_read(bench):
    from roboview.benchmark.format import load_benchmark
    from roboview.sim.observation import StaleObservation
    from roboview.tasks import load_task, make_env

    item = load_benchmark(bench, ["camera_pose"]).splits["camera_pose"][1]
    lazy, eager = (make_env(cameras=("front", "wrist"), image_size=48, lazy=flag) for flag in (True, False))
    expert = load_task().make_expert(eager)
    obs_lazy, _ = lazy.reset(seed=7, options={"instance": item.instance})
    obs_eager, _ = eager.reset(seed=7, options={"instance": item.instance})
    expert.reset()
    assert obs_lazy.rendered() == () and set(obs_lazy) == set(obs_eager)  # nothing rendered until read
    for step in range(5):  # the last (step 4) is not read
        if step % 2:  # read on odd steps only: skipped steps must not change what a later read shows
            for key in obs_eager:
                assert np.array_equal(obs_lazy[key], obs_eager[key]), (step, key)
            assert obs_lazy.rendered() == ("observation.images.front", "observation.images.wrist")
        action = expert.select_action(obs_eager)
        previous = obs_lazy
        obs_lazy, *_ = lazy.step(action)
        obs_eager, *_ = eager.step(action)
    assert previous.rendered() == ()
    with pytest.raises(StaleObservation, match="read after the env stepped on"):
        previous["observation.images.front"]
    assert np.array_equal(
        obs_lazy.materialize()["observation.images.wrist"], obs_eager["observation.images.wrist"]
    )
    lazy.close()
    eager.close()


def test_batched_lockstep_evaluation_agrees_row_for_row_with_one_env_per_worker(bench, tmp_path):
    # 3 envs per worker, 1 worker: episodes of unequal length share the worker, slots refill as they end.
    # camera_euler's first 8 instances span three contexts (three episode seeds, three episode lengths).
    one = evaluate(bench, tmp_path / "one", splits="camera_euler", limit=8, repeats=1, workers=1)
    three = evaluate(
        bench, tmp_path / "three", splits="camera_euler", limit=8, repeats=1, workers=1, envs_per_worker=3
    )
    eager = evaluate(
        bench, tmp_path / "eager", splits="camera_euler", limit=8, repeats=1, workers=1, eager=True
    )
    assert one.episodes == three.episodes == eager.episodes == 8
    pd.testing.assert_frame_equal(rows(tmp_path / "one"), rows(tmp_path / "three"))
    pd.testing.assert_frame_equal(rows(tmp_path / "one"), rows(tmp_path / "eager"))
    assert rows(tmp_path / "one")["steps"].nunique() > 1  # the episodes did end at different steps


def test_one_checkpoint_batch_equals_separate_calls(bench, tiny_checkpoint):
    from roboview.benchmark.format import load_benchmark
    from roboview.policies.base import Episode
    from roboview.policies.lerobot_policy import LeRobotPolicy
    from roboview.tasks import make_env

    items = load_benchmark(bench, ["color"]).splits["color"][:2]
    env = make_env(cameras=("left_top", "wrist"), image_size=64)
    observations, episodes = [], []
    for seed, item in enumerate(items):
        obs, _ = env.reset(seed=seed, options={"instance": item.instance})
        observations.append(obs)
        episodes.append(Episode.of(env, seed))
    env.close()
    single = LeRobotPolicy(str(tiny_checkpoint), "cpu")
    batched = LeRobotPolicy(str(tiny_checkpoint), "cpu", slots=2)
    for slot, episode in enumerate(episodes):
        batched.reset(episode, slot)
    expected = []
    for obs, episode in zip(observations, episodes):
        single.reset(episode)
        expected.append([single.select_action(obs) for _ in range(3)])  # the chunk's first three actions
    got = [batched.select_actions({0: observations[0], 1: observations[1]}) for _ in range(3)]
    assert batched.reads == 2 and single.reads == 2  # one model input per slot per chunk, not per step
    for step in range(3):
        for slot in range(2):
            np.testing.assert_allclose(got[step][slot], expected[slot][step], rtol=0, atol=1e-5)
    assert not np.allclose(expected[0][0], expected[1][0])  # two different episodes, two different actions


def test_failure_videos_decode_and_provenance_is_true(bench, tiny_checkpoint, tmp_path):
    import av
    import mujoco

    from roboview.eval.running.provenance import checkpoint_hash

    out = tmp_path / "ev"
    evaluate(
        bench,
        out,
        policy="lerobot",
        path=str(tiny_checkpoint),
        splits="color",
        limit=2,
        repeats=1,
        workers=1,
        max_steps=5,
        image_size=0,
        videos="failures",
    )
    df = pd.read_parquet(out / "episodes.parquet")
    assert (~df["success"]).all() and len(
        df
    ) == 2  # a 2-step checkpoint: every episode fails, every one filmed
    for row in df.itertuples():
        paths = row.video.split(",")
        assert [Path(p).name for p in paths] == [
            f"{row.instance_id}_r0_{cam}.mp4" for cam in ("left_top", "wrist")
        ]
        assert all(f"/color/{row.value}/" in f"/{p}" for p in paths)
        with av.open(str(out / paths[0])) as container:
            frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        assert len(frames) == row.steps + 1 and frames[0].shape == (64, 64, 3)  # every observation + the last
        assert frames[0].std() > 5  # a rendered scene, not a blank frame
    (entry,) = json.loads((out / "provenance.json").read_text())
    assert entry["packages"]["mujoco"] == mujoco.__version__
    assert entry["benchmark_version"] == json.loads((out / "run.json").read_text())["benchmark_version"]
    assert entry["checkpoint"]["sha256"] == checkpoint_hash(tiny_checkpoint)
    assert entry["checkpoint"]["config"]["type"] == "act"
    assert entry["machine"]["cpu_count"] == os.cpu_count() and entry["started"] <= entry["ended"]
    assert entry["episodes_run"] == 2 and "context_id" in entry["seed_rule"]
    assert entry["roboview_commit"] is None or len(entry["roboview_commit"].split("+")[0]) == 40
    # The report links every video from its per-value table and prints the provenance.
    from roboview.eval.reporting.report import load_results, write_report

    episodes, sources = load_results([out / "episodes.parquet"])
    report = (
        write_report(episodes, tmp_path / "report", sources=sources, plots=False).output_dir / "report.md"
    )
    text = report.read_text()
    first = df.iloc[0]
    assert f"../ev/videos/color/{first['value']}/{first['instance_id']}_r0_wrist.mp4" in text
    assert "## Provenance" in text and entry["checkpoint"]["sha256"][:16] in text
    # a resume adds an entry
    evaluate(
        bench,
        out,
        policy="lerobot",
        path=str(tiny_checkpoint),
        splits="color",
        limit=3,
        repeats=1,
        workers=1,
        max_steps=5,
        image_size=0,
    )
    assert [e["episodes_run"] for e in json.loads((out / "provenance.json").read_text())] == [2, 1]
    with pytest.raises(ValueError, match="allowed: a count N"):
        EvalConfig(videos="some")


def test_lerobot_eval_with_the_plugin_runs_the_same_episodes(bench, tiny_checkpoint, tmp_path):
    from roboview.integrations.lerobot.convert import convert

    # Two splits by name, as LeRobot's LIBERO integration takes suites; lerobot's default async vector envs.
    lerobot_eval = Path(sys.executable).parent / "lerobot-eval"
    args = [
        str(lerobot_eval),
        "--env.type=roboview",
        f"--env.benchmark_path={bench}",
        "--env.task=color,dist_scale",
        "--env.limit=2",
        "--env.cameras=left_top,wrist",
        "--env.image_size=64",
        "--env.max_steps=6",
        f"--policy.path={tiny_checkpoint}",
        "--policy.device=cpu",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
        f"--output_dir={tmp_path / 'le'}",
    ]
    proc = cli.run("lerobot.scripts.lerobot_eval", *args[1:])  # the lerobot-eval console script's module
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads((tmp_path / "le" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 4 and set(info["per_group"]) == {"color", "dist_scale"}
    assert [t["task_group"] for t in info["per_task"]] == ["color", "dist_scale"]
    converted = pd.read_parquet(
        convert(tmp_path / "le" / "eval_info.json", str(bench), tmp_path / "conv", limit=2)
    )
    evaluate(
        bench,
        tmp_path / "ours",
        policy="lerobot",
        path=str(tiny_checkpoint),
        splits="color,dist_scale",
        limit=2,
        repeats=1,
        workers=1,
        max_steps=6,
        image_size=0,
    )
    ours = pd.read_parquet(tmp_path / "ours" / "episodes.parquet")
    cols = ["split", "instance_id", "repeat", "episode_seed", "value", "success"]
    key = ["split", "instance_id", "repeat"]
    pd.testing.assert_frame_equal(
        converted[cols].sort_values(key).reset_index(drop=True),
        ours[cols].sort_values(key).reset_index(drop=True),
    )
    # eval_info.json carries each group's control arm beside pc_success, as the native run's metrics.json has it.
    from roboview.eval.statistics.metrics import MetricsConfig, compute_metrics

    groups = json.loads((tmp_path / "le" / "eval_info.json").read_text())["per_group"]
    native = compute_metrics(ours, MetricsConfig(n_perm=20, n_glm=5, max_perm=20))["splits"]
    assert groups["color"]["n_control_episodes"] >= 1  # the first instances of color hold its baseline value
    for split in ("color", "dist_scale"):
        assert "pc_success" in groups[split]
        assert (groups[split]["sr_control"], groups[split]["sr_control_ci95"]) == (
            native[split]["sr_control"],
            native[split]["sr_control_ci95"],
        )


def test_the_plugin_env_resets_lerobot_seeds_into_the_splits_episodes(bench):
    import gymnasium as gym
    from lerobot.envs.factory import make_env as lerobot_make_env
    from lerobot.envs.utils import preprocess_observation

    from roboview.benchmark.format import load_benchmark
    from roboview.integrations.lerobot import RoboViewEnv
    from roboview.tasks import make_env
    from roboview.variation.instances import episode_seed

    cfg = RoboViewEnv(
        benchmark_path=str(bench), task="color", cameras="front", image_size=48, n_repeats=2, max_steps=50
    )
    vec = lerobot_make_env(cfg, n_envs=2)["color"][0]  # lerobot's own factory: one vector env per split
    assert isinstance(vec, gym.vector.SyncVectorEnv) and vec.call("_max_episode_steps")[0] == 50
    assert list(vec.call("task")) == ["color", "color"]
    obs, _ = vec.reset(seed=[1000 + 2, 1000 + 3])  # episodes 2 and 3: instance 1, repeats 0 and 1
    batch = preprocess_observation(obs)
    item = load_benchmark(bench, ["color"]).splits["color"][1]
    assert list(vec.call("task_description")) == [item.instance.get("instruction")] * 2
    env = make_env(cameras=("front",), image_size=48)
    for slot, repeat in enumerate((0, 1)):
        own, _ = env.reset(
            seed=episode_seed(item.record["context_id"], repeat), options={"instance": item.instance}
        )
        expected = own["observation.images.front"].astype(np.float32) / 255
        assert np.array_equal(batch["observation.images.front"][slot].permute(1, 2, 0).numpy(), expected)
    env.close()
    vec.close()
    assert list(RoboViewEnv(benchmark_path=str(bench), task="all").splits()) == list(
        load_benchmark(bench).splits
    )
    with pytest.raises(ValueError, match="allowed: front, left_top, right_top, wrist"):
        RoboViewEnv(benchmark_path=str(bench), cameras="overhead")
    with pytest.raises(ValueError, match="colour"):
        RoboViewEnv(benchmark_path=str(bench), task="colour").splits()


def test_a_policy_server_feeds_every_worker_from_one_model(bench, tiny_checkpoint, tmp_path):
    common = dict(
        policy="lerobot",
        path=str(tiny_checkpoint),
        splits="color,camera_pose",
        limit=3,
        repeats=1,
        max_steps=6,
        image_size=0,
    )
    served = evaluate(bench, tmp_path / "served", workers=2, envs_per_worker=2, policy_server=True, **common)
    evaluate(bench, tmp_path / "alone", workers=1, **common)
    cols = ["instance_id", "repeat", "episode_seed", "success", "steps", "policy", "failure_reason"]
    assert served.episodes == 6
    pd.testing.assert_frame_equal(rows(tmp_path / "served")[cols], rows(tmp_path / "alone")[cols])
    with pytest.raises(ValueError, match="needs a policy with one batched model"):
        evaluate(bench, tmp_path / "expert", policy_server=True)


def test_inference_threads_fit_the_free_cores(monkeypatch):
    """Threads per worker: the cores not already busy, split between the workers, at least one; the flag wins."""
    import roboview.core.workers as workers

    monkeypatch.setattr(workers.os, "cpu_count", lambda: 8)
    monkeypatch.setattr(workers.os, "getloadavg", lambda: (0.2, 0.0, 0.0))
    assert [workers.threads_per_worker(n) for n in (1, 2, 3, 8, 16)] == [7, 3, 2, 1, 1]
    monkeypatch.setattr(workers.os, "getloadavg", lambda: (7.5, 0.0, 0.0))  # a busy machine: one thread each
    assert workers.threads_per_worker(1) == 1 and workers.threads_per_worker(1, requested=4) == 4
    with pytest.raises(ValueError, match="--eval.torch_threads=-1 must be ≥ 0"):
        EvalConfig(torch_threads=-1)
