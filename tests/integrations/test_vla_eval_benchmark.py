"""RoboView inside vla-eval: vla-eval's own CLI runs the RoboView benchmark against model servers on 127.0.0.1,
and its results, converted, equal a native roboview.pipelines.evaluate run of the same episodes."""

import contextlib
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import anyio
import numpy as np
import pandas as pd
import pytest
from vla_eval.model_servers.predict import PredictModelServer
from vla_eval.model_servers.serve import serve_async
from vla_eval.orchestrator import Orchestrator
from vla_eval.results.export import export_eval
from vla_eval.specs import (
    GRIPPER_01,
    GRIPPER_CLOSE_POS,
    IMAGE_RGB,
    LANGUAGE,
    POSITION_ABSOLUTE,
    POSITION_DELTA,
    ROTATION_AA,
    STATE_EEF_POS_AA_GRIP,
    STATE_JOINT,
)

from roboview.benchmark.format import load_benchmark
from roboview.integrations.vla_eval.benchmark import RoboViewBenchmark
from roboview.integrations.vla_eval.convert import convert, read_aggregates
from roboview.policies.serving.vla_eval_specs import JOINT_TARGETS
from roboview.tasks import load_task, make_env
from roboview.variation.instances import episode_seed

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "vla_eval" / "roboview_tiny.yaml"
SPLIT = "color_x_camera_pose"  # the tiny benchmark's smallest split: 6 instances of one context
ROW_COLUMNS = [
    "split",
    "instance_id",
    "repeat",
    "value",
    "episode_seed",
    "success",
    "steps",
    "failure_reason",
    "isolation",
    "status",
    "conformance",
]


class ReplayServer(PredictModelServer):
    """Replays a recorded action list per (instance, repeat): the task fields vla-eval sends at episode start."""

    def __init__(self, actions: dict[tuple[str, int], list[np.ndarray]]) -> None:
        super().__init__()
        self.actions, self.queues = actions, {}

    def get_action_spec(self):
        return {"joints": JOINT_TARGETS, "gripper": GRIPPER_01}

    def get_observation_spec(self):
        return {"state": STATE_JOINT, "language": LANGUAGE}

    async def on_episode_start(self, config, ctx) -> None:
        task = config["task"]
        self.queues[ctx.session_id] = list(self.actions[(task["instance_id"], task["repeat"])])
        await super().on_episode_start(config, ctx)

    def predict(self, obs, ctx):
        queue = self.queues[ctx.session_id]
        return {"actions": queue.pop(0) if len(queue) > 1 else queue[0]}


class EEReplayServer(ReplayServer):
    """The replay in LIBERO's conventions: position and axis-angle deltas, gripper +1 = close, the EE state in."""

    def get_action_spec(self):
        return {"position": POSITION_DELTA, "rotation": ROTATION_AA, "gripper": GRIPPER_CLOSE_POS}

    def get_observation_spec(self):
        return {"state": STATE_EEF_POS_AA_GRIP, "language": LANGUAGE}


class FailingServer(ReplayServer):
    async def on_episode_start(self, config, ctx) -> None:
        await PredictModelServer.on_episode_start(self, config, ctx)

    def predict(self, obs, ctx):
        raise RuntimeError("model crashed")


@contextlib.contextmanager
def served(server):
    """`server` on ws://127.0.0.1:PORT in a thread (vla-eval's own serve_async); yields the URL."""
    ready, stop, port = threading.Event(), threading.Event(), []

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            port.append(await tg.start(serve_async, server, "127.0.0.1", 0))
            ready.set()
            await anyio.to_thread.run_sync(stop.wait)
            tg.cancel_scope.cancel()

    thread = threading.Thread(target=anyio.run, args=(main,), daemon=True)
    thread.start()
    assert ready.wait(30), "the model server did not start"
    try:
        yield f"ws://127.0.0.1:{port[0]}"
    finally:
        stop.set()
        thread.join(10)


def expert_actions(bench: Path, split: str, repeats: int, max_steps: int, control: str = "joint") -> dict:
    """The scripted expert's actions in each (instance, repeat) of `split`, recorded as roboview.pipelines.evaluate runs it."""
    env = make_env(cameras=("left_top",), image_size=64, max_steps=max_steps, lazy=True, control=control)
    out = {}
    for item in load_benchmark(bench, [split]).splits[split]:
        for repeat in range(repeats):
            env.reset(
                seed=episode_seed(item.record["context_id"], repeat), options={"instance": item.instance}
            )
            expert = load_task(item.instance.task).make_expert(env)
            expert.reset()
            actions, done = [], False
            while not done:
                actions.append(expert.select_action(None))
                _, _, success, truncated, _ = env.step(actions[-1])
                done = success or truncated
            out[(item.record["instance_id"], repeat)] = actions
    env.close()
    return out


def table(path: Path) -> pd.DataFrame:
    df = pd.read_parquet(path)
    return df[ROW_COLUMNS].sort_values(["instance_id", "repeat"]).reset_index(drop=True)


def test_vla_eval_runs_the_benchmark_and_its_results_convert_to_the_native_run(tiny_benchmark, tmp_path):
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.pipelines.report import ReportConfig
    from roboview.pipelines.report import run as report
    from roboview.pipelines.verify import VerifyConfig
    from roboview.pipelines.verify import run as verify
    from roboview.policies.types import policy_config

    repeats, max_steps = 2, 60
    actions = expert_actions(tiny_benchmark, SPLIT, repeats, max_steps)
    with served(ReplayServer(actions)) as url:
        proc = subprocess.run(
            [
                str(Path(sys.executable).parent / "vla-eval"),
                "run",
                "-c",
                str(CONFIG),
                "--no-docker",
                "--server-url",
                url,
                "--output-dir",
                str(tmp_path / "vla"),
                "--param",
                f"benchmark_path={tiny_benchmark}",
                "--param",
                f"splits={SPLIT}",
                "--param",
                "limit=0",
                "--param",
                f"n_repeats={repeats}",
                "--param",
                "send_images=false",  # the replay reads none: no camera renders
            ],
            capture_output=True,
            text=True,
            timeout=300,
            env=os.environ | {"PYTHONPATH": str(ROOT)},
        )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Spec validation passed" in proc.stderr
    aggregate = json.loads((tmp_path / "vla" / "RoboView_aggregate.json").read_text())
    assert aggregate["num_episodes_total"] == 6 * repeats and aggregate["num_errors"] == 0
    # RoboView's episodes carry their context: the audit maps split, value, context and repeat by default.
    from roboview.pipelines.audit import main as audit

    audit([f"--results={tmp_path / 'vla'}", "--format=vla_eval", f"--output_dir={tmp_path / 'audit'}",
           "--metrics.n_perm=50", "--metrics.n_glm=10", "--metrics.max_perm=50"])  # fmt: skip
    audited = json.loads((tmp_path / "audit" / "metrics.json").read_text())["splits"][SPLIT]
    assert audited["n_contexts"] == 1 and audited["n_episodes"] == 6 * repeats
    assert {v["n_episodes"] for v in audited["per_value"].values()} == {repeats} and audited["sr"] == 1.0

    converted = tmp_path / "converted"
    convert(
        tmp_path / "vla" / "RoboView_aggregate.json", str(tiny_benchmark), converted, policy_name="expert"
    )
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(tiny_benchmark), SPLIT),
            policy_config("expert"),
            EvalConfig(n_repeats=repeats, num_workers=1, image_size=64, max_steps=max_steps),
            str(tmp_path / "native"),
        )
    )
    ours, theirs = table(tmp_path / "native" / "episodes.parquet"), table(converted / "episodes.parquet")
    pd.testing.assert_frame_equal(theirs, ours)
    # A comparison that could fail: each row's isolation certificate hashes the seed, the object's initial pose and
    # the cameras the episode was reset to, and the two repeats differ in it; the replayed expert succeeds in all.
    by_repeat = theirs.groupby("repeat")["isolation"].agg(set)
    assert not by_repeat[0] & by_repeat[1] and theirs["success"].all()

    metrics = []
    for name, folder in (("native", tmp_path / "native"), ("converted", converted)):
        report(ReportConfig(results=str(folder), output_dir=str(tmp_path / f"report_{name}"), plots=False))
        metrics.append(json.loads((tmp_path / f"report_{name}" / "metrics.json").read_text()))
        metrics[-1].pop("sources")  # the file's path and the command that wrote it
    assert metrics[0] == metrics[1]
    checked = verify(VerifyConfig(results=str(converted)))
    assert checked.passed, [(c.name, c.detail) for c in checked.checks if not c.passed]
    # The sqlite recording, through vla-eval's own exporter, gives the same table.
    (db,) = (tmp_path / "vla").glob("recording-*.sqlite")
    convert(db, "", tmp_path / "from_db", policy_name="expert")
    pd.testing.assert_frame_equal(table(tmp_path / "from_db" / "episodes.parquet"), ours)


def orchestrate(url: str, out: Path, **params) -> list[dict]:
    """The config's entry with `params`, run by vla-eval's Orchestrator in this process, then its export."""
    from vla_eval.cli.config_loader import load_config

    config = load_config(str(CONFIG))
    config["server"]["url"], config["output_dir"] = url, str(out)
    config["benchmarks"][0]["params"].update(params)
    orchestrator = Orchestrator(config)
    anyio.run(orchestrator.run)
    return export_eval(out, orchestrator.eval_id)


def test_vla_evals_lerobot_server_runs_a_roboview_checkpoint_as_roboview_does(
    tiny_benchmark, tiny_checkpoint, tmp_path
):
    from vla_eval.model_servers.lerobot import LeRobotModelServer

    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.policies.types import policy_config

    server = LeRobotModelServer(
        "act",
        str(tiny_checkpoint),
        image_keys={c: f"observation.images.{c}" for c in ("left_top", "wrist")},
        device="cpu",
    )
    with served(server) as url:
        (aggregate,) = orchestrate(
            url, tmp_path / "vla", benchmark_path=str(tiny_benchmark), limit=2, max_steps=6
        )
    assert aggregate["server_info"]["model_server"] == "LeRobotModelServer" and aggregate["num_errors"] == 0
    convert(tmp_path / "vla", str(tiny_benchmark), tmp_path / "converted", policy_name="act")
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(tiny_benchmark), "color"),
            policy_config("lerobot", path=str(tiny_checkpoint)),
            EvalConfig(n_repeats=1, limit=2, num_workers=1, max_steps=6),
            str(tmp_path / "native"),
        )
    )
    native = table(tmp_path / "native" / "episodes.parquet")
    pd.testing.assert_frame_equal(table(tmp_path / "converted" / "episodes.parquet"), native)
    assert list(native["steps"]) == [6, 6] and native["failure_reason"].str.endswith("within 6 steps").all()


class SeeingFailingServer(FailingServer):
    def get_observation_spec(self):
        return {"left_top": IMAGE_RGB, "state": STATE_JOINT, "language": LANGUAGE}


def test_a_model_that_raises_is_the_policys_failure_through_vla_eval_as_through_the_client(
    tiny_benchmark, tmp_path
):
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.pipelines.verify import VerifyConfig
    from roboview.pipelines.verify import run as verify
    from roboview.policies.types import policy_config

    with served(SeeingFailingServer({})) as url:  # its predict raises
        orchestrate(
            url, tmp_path / "vla", benchmark_path=str(tiny_benchmark), limit=1, image_size=64, max_steps=3
        )
        evaluate(
            EvaluateConfig(
                BenchmarkConfig(str(tiny_benchmark), "color"),
                policy_config("vla_eval", url=url, image_size=64),
                EvalConfig(n_repeats=1, limit=1, num_workers=1, max_steps=3),
                str(tmp_path / "client"),
            )
        )
    rows = pd.read_parquet(convert(tmp_path / "vla", "", tmp_path / "converted"))
    client = pd.read_parquet(tmp_path / "client" / "episodes.parquet")
    # One rule: counted (status ok), failed, with the model's own message, on both paths.
    for table_ in (rows, client):
        assert list(table_["status"]) == ["ok"] and not table_["success"].any(), table_["failure_reason"][0]
        assert (
            table_["failure_reason"][0].startswith("policy error: ")
            and "model crashed" in table_["failure_reason"][0]
        )
    # The certificate vla-eval did not return is re-derived: the one the client's episode measured.
    assert (
        rows["isolation"][0] == client["isolation"][0]
        and rows["episode_seed"][0] == client["episode_seed"][0]
    )
    checks = {c.name: c for c in verify(VerifyConfig(results=str(tmp_path / "converted"))).checks}
    assert checks["isolation"].passed and checks["conformance"].passed, checks["conformance"].detail
    entries = json.loads((tmp_path / "converted" / "provenance.json").read_text())
    assert entries[-1]["isolation_rederived"] == 1
    assert entries[-1]["benchmark_path"] == str(Path(tiny_benchmark).resolve())
    other = read_aggregates(tmp_path / "vla")[0] | {"config": {"benchmark": "x:Other"}}
    (tmp_path / "other.json").write_text(json.dumps(other))
    with pytest.raises(
        ValueError, match="hold no roboview.integrations.vla_eval.benchmark:RoboViewBenchmark entry"
    ):
        convert(tmp_path / "other.json", str(tiny_benchmark), tmp_path / "other")


def test_an_episode_lost_to_the_connection_is_infrastructure_and_verify_names_the_benchmark(
    tiny_benchmark, tmp_path
):
    from roboview.eval.verification.results import benchmark_path

    with served(FailingServer({})) as url:
        orchestrate(
            url, tmp_path / "vla", benchmark_path=str(tiny_benchmark), limit=1, send_images=False, max_steps=3
        )
    aggregate = read_aggregates(tmp_path / "vla")[0]
    for task in aggregate["tasks"]:
        for episode in task["episodes"]:
            episode["failure_reason"], episode["failure_detail"] = "connection_closed", "code=1006 reason="
    (tmp_path / "lost.json").write_text(json.dumps(aggregate))
    rows = pd.read_parquet(convert(tmp_path / "lost.json", str(tiny_benchmark), tmp_path / "converted"))
    assert list(rows["status"]) == ["infra_error"]
    assert rows["failure_reason"][0] == "infrastructure error: vla-eval connection_closed: code=1006 reason="
    # No episode returned the benchmark's record, yet the folder names the benchmark convert was given.
    assert benchmark_path(tmp_path / "converted") == Path(tiny_benchmark).resolve()


def test_specs_follow_the_control_and_bad_params_fail_before_any_episode(tiny_benchmark):
    bench = str(tiny_benchmark)
    joint = RoboViewBenchmark(bench, "color", cameras="left_top,wrist")
    assert joint.get_action_spec() == {"joints": JOINT_TARGETS, "gripper": GRIPPER_01}
    assert joint.get_observation_spec() == {
        "left_top": IMAGE_RGB,
        "wrist": IMAGE_RGB,
        "language": LANGUAGE,
        "state": STATE_JOINT,
    }
    ee = {"gripper": GRIPPER_CLOSE_POS, "rotation": ROTATION_AA}
    assert RoboViewBenchmark(bench, "color", control="ee_delta").get_action_spec() == ee | {
        "position": POSITION_DELTA
    }
    ee_abs = RoboViewBenchmark(bench, "color", control="ee_abs", send_images=False)
    assert ee_abs.get_action_spec() == ee | {"position": POSITION_ABSOLUTE}
    assert ee_abs.get_observation_spec() == {"language": LANGUAGE, "state": STATE_EEF_POS_AA_GRIP}
    tasks = RoboViewBenchmark(bench, "color,dist_scale", n_repeats=2, contexts=1).get_tasks()
    items = load_benchmark(bench, ["color"]).splits["color"]
    first = [i for i in items if i.record["context_id"] == items[0].record["context_id"]]
    assert [(t["instance_id"], t["repeat"]) for t in tasks[: 2 * len(first)]] == [
        (i.record["instance_id"], r) for i in first for r in (0, 1)
    ]
    assert tasks[1]["episode_seed"] == episode_seed(first[0].record["context_id"], 1)
    assert {t["suite"] for t in tasks} == {"color", "dist_scale"}
    for params, message in (
        ({"control": "cartesian"}, "allowed: joint, ee_delta, ee_abs"),
        ({"splits": "colour"}, "unknown split.*colour.*color"),
        ({"cameras": "top"}, "allowed: front, left_top, right_top, wrist"),
        ({"n_repeats": 0}, "params.n_repeats=0 must be a positive count"),
        ({"benchmark_path": "/nonexistent"}, "no such folder"),
    ):
        with pytest.raises(ValueError, match=message):
            RoboViewBenchmark(**({"benchmark_path": bench} | params))
    with pytest.raises(ValueError, match="set episodes_per_task: 1"):
        joint.reset(tasks[0] | {"episode_idx": 1})
    # A malformed action ends the episode as the policy's failure (as in roboview.pipelines.evaluate), not as an error.

    async def malformed_action() -> dict:
        await joint.start_episode(joint.get_tasks()[0])
        await joint.apply_action({"actions": np.zeros(7, dtype=np.float32)})
        assert await joint.is_done()
        return await joint.get_result()

    result = anyio.run(malformed_action)
    assert not result["success"] and result["steps"] == 0 and result["repeat"] == 0
    assert result["failure_reason"].startswith("policy error: action of shape (7,)")
    joint.cleanup()


def test_vla_eval_runs_the_benchmark_in_end_effector_control(tiny_benchmark, tmp_path):
    """`params.control: ee_delta`: a server in LIBERO's conventions (the expert's EE actions, replayed) gives the
    rows of the expert run natively in ee_delta."""
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.policies.types import policy_config

    max_steps = 60
    actions = expert_actions(tiny_benchmark, SPLIT, 1, max_steps, control="ee_delta")
    assert all(np.all(np.abs(a) <= 1) and a.shape == (7,) for run in actions.values() for a in run)
    with served(EEReplayServer(actions)) as url:
        (aggregate,) = orchestrate(
            url,
            tmp_path / "vla",
            benchmark_path=str(tiny_benchmark),
            splits=SPLIT,
            limit=0,
            n_repeats=1,
            max_steps=max_steps,
            control="ee_delta",
            send_images=False,
        )
    assert aggregate["num_errors"] == 0
    convert(tmp_path / "vla", str(tiny_benchmark), tmp_path / "converted", policy_name="expert")
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(tiny_benchmark), SPLIT),
            policy_config("expert", control="ee_delta"),
            EvalConfig(n_repeats=1, num_workers=1, image_size=64, max_steps=max_steps),
            str(tmp_path / "native"),
        )
    )
    native = table(tmp_path / "native" / "episodes.parquet")
    pd.testing.assert_frame_equal(table(tmp_path / "converted" / "episodes.parquet"), native)
    assert len(native) == 6 and native["success"].all()


def test_a_bad_param_ends_vla_eval_run_with_one_line_before_any_episode(tiny_benchmark, tmp_path):
    with served(ReplayServer({})) as url:
        for param, message in (
            (f"benchmark_path={tmp_path / 'nope'}", "no such folder (a benchmark folder written by"),
            ("splits=colour", "params.splits='colour': unknown split(s) ['colour']"),
        ):
            proc = subprocess.run(
                [str(Path(sys.executable).parent / "vla-eval"), "run", "-c", str(CONFIG), "--no-docker",
                 "--server-url", url, "--output-dir", str(tmp_path / "vla"),
                 "--param", f"benchmark_path={tiny_benchmark}", "--param", param],
                capture_output=True, text=True, timeout=120, env=os.environ | {"PYTHONPATH": str(ROOT)},
            )  # fmt: skip
            assert proc.returncode == 2, proc.stderr[-2000:]
            assert "Traceback" not in proc.stderr and proc.stderr.strip().splitlines()[-1].startswith(
                "error: params."
            )
            assert message in proc.stderr
    assert not list((tmp_path / "vla").glob("*.json"))  # no result, no aggregate


def test_the_documented_vla_eval_run_writes_under_a_git_ignored_folder():
    import yaml

    out = yaml.safe_load(CONFIG.read_text())["output_dir"]
    assert out == "outputs/vla_eval"
    ignored = subprocess.run(["git", "check-ignore", "-q", f"{out}/recording-x.sqlite"], cwd=ROOT)
    assert ignored.returncode == 0  # git check-ignore: 0 = ignored
