"""Episodes ended by infrastructure are not policy failures: `status` infra_error, counted in no rate, run again.

In-process: a transient error still failing after its retries, an `InfraError`, a render failure, a frame that cannot
be right (all black, in RoboView's and LIBERO's scenes made dark through their model arrays; a Meta-World frame frozen
by another MuJoCo renderer made in the process) and a worker that keeps dying become infra_error rows while a
policy's own exception stays an `ok` failure, and a dark frame that is not constant passes; the evaluator re-runs
infra rows after its pass and on a rerun (the new row replaces the old one); adaptive decisions, metrics and the
report leave them out. Against real servers on 127.0.0.1 (openpi-server's `WebsocketPolicyServer` via
`roboview.pipelines.serve_policy --server=openpi`, and lerobot's own `lerobot.async_inference.policy_server`): the server is
killed mid-run and restarted within the client's reconnect window; the interrupted episode is recorded
infra_error, left out of the report, re-run by the same command, and the final table is complete and all `ok`.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest

from roboview.eval.running.results import INFRA_ERROR, EpisodeStore, read_journal
from roboview.eval.statistics.metrics import MetricsConfig, compute_all_metrics, policy_layouts
from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
from roboview.policies.base import PolicyConfig, TransientPolicyError
from roboview.policies.errors import InfraError, RenderError
from roboview.policies.types import policy_config
from tests.helpers.servers import LeRobotServer

pytestmark = pytest.mark.slow

FAST = MetricsConfig(n_perm=50, n_glm=10)


# -- policies built in spawned workers: module-level classes, so the workers can unpickle their configs -----------


class _Still:
    """Holds the arm where it is (every episode fails at max_steps): `status` ok."""

    name = "still"
    failure_reason = ""

    def reset(self, episode) -> None:
        pass

    def select_action(self, observation):
        return np.append(np.asarray(observation["observation.state"])[:7], 0.0).astype(np.float32)

    def close(self) -> None:
        pass


class _LosesItsServerOnce(_Still):
    """The first reset of the whole run (a marker file remembers it across workers) raises InfraError."""

    def __init__(self, marker: str) -> None:
        self.marker = Path(marker)

    def reset(self, episode) -> None:
        if not self.marker.exists():
            self.marker.touch()
            raise InfraError("the policy server went away mid-episode (test)")


@dataclass
class OnceConfig(PolicyConfig):
    marker: str = ""

    def build(self, view):
        return _LosesItsServerOnce(self.marker)


class _Dies(_Still):
    def reset(self, episode) -> None:
        os._exit(3)  # the worker process dies, as a segfaulting renderer or an OOM kill would end it


@dataclass
class DyingConfig(PolicyConfig):
    def build(self, view):
        return _Dies()


class _Scripted(_Still):
    """Raises `errors` from select_action, one per call (None: answer), reading an image first if `look`."""

    def __init__(self, errors, look: bool = False) -> None:
        self.errors, self.look, self.calls = list(errors), look, 0

    def select_action(self, observation):
        self.calls += 1
        if self.look:
            observation[next(k for k in observation if k.startswith("observation.images."))]
        error = self.errors.pop(0) if self.errors else None
        if error is not None:
            raise error
        return super().select_action(observation)


@dataclass
class ScriptedConfig(PolicyConfig):
    def build(self, view):
        return self.policy  # set by the test on the instance (in-process worker only)


def _darken(model) -> tuple:
    """Every light off, the headlight's ambient and diffuse too, and every geom black and matte, through the model's
    arrays: the camera then renders all 0. Returns what `_undarken` puts back."""
    head = model.vis.headlight
    saved = (
        model.light_active.copy(),
        int(head.active),
        head.ambient.copy(),
        head.diffuse.copy(),
        model.geom_rgba.copy(),
        model.geom_matid.copy(),
    )
    model.light_active[:], head.active, head.ambient[:], head.diffuse[:] = 0, 0, 0, 0
    model.geom_rgba[:], model.geom_matid[:] = (0, 0, 0, 1), -1
    return saved


def _undarken(model, saved: tuple) -> None:
    head = model.vis.headlight
    model.light_active[:], head.active, head.ambient[:], head.diffuse[:] = saved[:4]
    model.geom_rgba[:], model.geom_matid[:] = saved[4:]


class _DarkensOnce(_Still):
    """Privileged: the first episode of the whole run (a marker file remembers it across workers) it darkens its env
    (`_darken`) after the reset, reads the first camera (rendered all 0) and puts the scene back; then it holds the
    arm (joint control) or sends zero deltas. Every other episode it reads the camera of a normal scene."""

    def __init__(self, env, marker: str) -> None:
        self.env, self.marker, self.saved = env, Path(marker), None

    def reset(self, episode) -> None:
        if not self.marker.exists():
            self.marker.touch()
            self.saved = _darken(self.env.model)

    def select_action(self, observation):
        observation[f"observation.images.{self.env.cameras[0]}"]
        if self.saved is not None:
            _undarken(self.env.model, self.saved)
            self.saved = None
        if self.env.control == "joint":
            return super().select_action(observation)
        return np.zeros(self.env.action_space.shape, np.float32)


@dataclass
class DarkOnceConfig(PolicyConfig):
    privileged: ClassVar[bool] = True
    marker: str = ""
    control: str = "joint"

    def build(self, env):
        return _DarkensOnce(env, self.marker)

    def env_control(self) -> str:
        return self.control


class _LooksOnce(_Still):
    """Reads Meta-World's camera at the first step of each episode only (as the `vision` agent reads one frame per
    episode) and pushes the hand along x."""

    def reset(self, episode) -> None:
        self.looked = False

    def select_action(self, observation):
        if not self.looked:
            self.looked = observation["observation.images.corner2"] is not None
        return np.array([0.5, 0.0, 0.0, 0.0], np.float32)


@dataclass
class LooksOnceConfig(PolicyConfig):
    def build(self, view):
        return _LooksOnce()

    def observed_cameras(self) -> tuple[str, ...]:
        return ("corner2",)

    def env_control(self) -> str:
        return "xyz_delta"


def _item(bench: Path, split: str = "color", index: int = 0):
    from roboview.benchmark.format import load_benchmark

    return load_benchmark(bench, [split]).splits[split][index]


def _cfg(
    bench: Path, out: Path, policy, splits="color", limit=2, workers=1, max_steps=3, retries=2
) -> EvaluateConfig:
    return EvaluateConfig(
        BenchmarkConfig(path=str(bench), splits=splits),
        policy,
        EvalConfig(
            n_repeats=1,
            limit=limit,
            num_workers=workers,
            max_steps=max_steps,
            image_size=0,
            max_infra_retries=retries,
        ),
        str(out),
    )


def _rows(out: Path) -> pd.DataFrame:
    return (
        pd.read_parquet(out / "episodes.parquet")
        .sort_values(["instance_id", "repeat"])
        .reset_index(drop=True)
    )


# -- what is an infrastructure error -----------------------------------------------------------------------------


def test_an_outage_past_the_retries_is_infra_and_a_policy_bug_is_not(tiny_benchmark, monkeypatch):
    import roboview.eval.running.rollout as rollout

    monkeypatch.setattr(rollout, "RETRY_BACKOFF_S", 0.0)
    config = ScriptedConfig()
    config.policy = _Scripted([])
    worker = rollout.EvalWorker(rollout.WorkerSpec(config, image_size=32, max_steps=3))
    item = _item(tiny_benchmark)
    cases = [  # (errors, status, steps, calls, reason)
        (
            [TransientPolicyError("503 from the endpoint")] * 3,
            INFRA_ERROR,
            0,
            3,
            "policy error after 2 retries: TransientPolicyError: 503 from the endpoint",
        ),
        ([ValueError("bad output")], "ok", 0, 1, "policy error: ValueError: bad output"),
        ([InfraError("server lost")], INFRA_ERROR, 0, 1, "infrastructure error: InfraError: server lost"),
        # retried, then the policy's own failure
        ([TimeoutError("slow"), None], "ok", 3, 4, "within 3 steps"),
    ]
    try:
        for errors, status, steps, calls, reason in cases:
            config.policy = _Scripted(errors)
            worker.batch = rollout.make_policy_batch(config, worker.envs)
            row = worker.run(rollout.WorkItem(item, 0)).row
            assert (row["status"], row["steps"], config.policy.calls) == (status, steps, calls), errors
            assert reason in row["failure_reason"] and not row["success"]
    finally:
        worker.close()


def test_a_render_failure_is_an_infra_error(tiny_benchmark):
    import roboview.eval.running.rollout as rollout

    config = ScriptedConfig()
    config.policy = _Scripted([], look=True)
    worker = rollout.EvalWorker(rollout.WorkerSpec(config, image_size=32, max_steps=3))
    item = _item(tiny_benchmark)
    try:
        assert worker.run(rollout.WorkItem(item, 0)).row["status"] == "ok"  # renders fine

        def lost(*_):
            raise RuntimeError("GL context lost")

        env = worker.envs[0]
        env.renderer.render = lost
        with pytest.raises(
            RenderError, match="rendering camera 'front' failed: RuntimeError: GL context lost"
        ):
            env.render_camera("front")
        with pytest.raises(KeyError):  # a wrong camera name is the caller's error, not the renderer's
            env.render_camera("no_such_camera")
        row = worker.run(rollout.WorkItem(item, 0)).row  # the policy reads an image: it does not render
        assert row["status"] == INFRA_ERROR and "RenderError: rendering camera" in row["failure_reason"]
        config.policy = _Scripted([])  # a policy that reads no image never renders: its episode is its own
        worker.batch = rollout.make_policy_batch(config, worker.envs)
        assert worker.run(rollout.WorkItem(item, 0)).row["status"] == "ok"
    finally:
        worker.close()


GL_CAUSE = "another renderer in this process may have taken the GL context"


def test_a_black_frame_is_an_infra_error_left_out_of_the_rates_and_run_again(
    tiny_benchmark, tmp_path, monkeypatch
):
    """RoboView's scene renders all 0 for the first episode of the run: its row is infra_error naming the camera,
    the metrics leave it out, and the same command runs it again."""
    monkeypatch.setitem(PolicyConfig.get_known_choices(), "dark_once", DarkOnceConfig)
    out = tmp_path / "ev"
    cfg = _cfg(tiny_benchmark, out, DarkOnceConfig(marker=str(tmp_path / "dark")), retries=0)
    first = run(cfg)
    rows = _rows(out)
    assert first.infra_errors == 1 and sorted(rows["status"]) == [INFRA_ERROR, "ok"]
    dark = rows[rows["status"] == INFRA_ERROR].iloc[0]
    assert dark["failure_reason"] == (
        f"infrastructure error: RenderError: render: camera front returned a constant frame (all 0) — {GL_CAUSE}"
    )
    assert dark["steps"] == 0 and not dark["success"]  # ended before the env stepped on the frame
    color = compute_all_metrics(rows, FAST)["splits"]["color"]
    assert color["n_infra_errors"] == 1 and color["n_episodes"] == 1
    assert color["sr"] == rows.loc[rows["status"] == "ok", "success"].mean()
    again = run(cfg)  # resumed: only the infra one runs, on a scene that renders
    rows = _rows(out)
    assert again.new_episodes == 1 and again.infra_errors == 0 and (rows["status"] == "ok").all()
    assert len(rows) == 2 and not rows.duplicated(["instance_id", "repeat"]).any()


def test_a_black_frame_is_an_infra_error_on_liberos_scenes(tmp_path):
    pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
    from roboview.benchmark.format import BenchmarkItem
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.libero.task import baseline_libero_instance

    instance = baseline_libero_instance("libero_object/0", "1")
    work = WorkItem(BenchmarkItem(instance, instance.to_record()), 0)
    config = DarkOnceConfig(marker=str(tmp_path / "dark"), control="ee_delta")
    worker = EvalWorker(WorkerSpec(config, image_size=64, max_steps=3, task="libero"))
    try:
        dark, lit, again = (worker.run(work).row for _ in range(3))
    finally:
        worker.close()
    assert dark["status"] == INFRA_ERROR and dark["failure_reason"].endswith(
        f"render: camera agentview returned a constant frame (all 0) — {GL_CAUSE}"
    )
    # The same context and repeat run again start from the state the last frame was taken in: not flagged.
    assert lit["status"] == again["status"] == "ok" and again["steps"] == 3


def test_another_mujoco_renderer_leaves_metaworld_frames_right_and_a_frozen_frame_is_an_infra_error():
    """The real failure: a second MuJoCo renderer made and used in the process left its GL context current, and
    Meta-World's renderer (gymnasium's, which does not make its own context current) read back a frame that no longer
    changed with the scene. The scene now makes its context current before it renders: its frames follow the hand.
    A frame frozen across a reset that moved the scene (what that failure handed the policy) is an infra error."""
    pytest.importorskip("metaworld", reason="Meta-World not installed (make install-metaworld)")
    import mujoco

    from roboview.benchmark.format import BenchmarkItem
    from roboview.eval.running.frames import FrameCheck
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.metaworld.task import baseline_metaworld_instance

    instance = baseline_metaworld_instance()
    item = BenchmarkItem(instance, instance.to_record())
    worker = EvalWorker(WorkerSpec(LooksOnceConfig(), image_size=64, max_steps=4, task="metaworld"))
    other = None
    try:
        first = worker.run(WorkItem(item, 0)).row
        assert first["status"] == "ok"
        model = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><light pos='0 0 1'/><geom type='sphere' size='.1'/></worldbody></mujoco>"
        )
        other = mujoco.Renderer(model, 64, 64)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        other.update_scene(data)
        other.render()
        moving = worker.run(WorkItem(item, 1, video=True))
        frames = moving.video["corner2"]
        assert len(frames) == 5 and not (frames == frames[0]).all()  # 4 steps of the hand moving: it moves
        assert moving.row["status"] == "ok"
        # The frame the last episode ended on, handed again after a reset that moved the puck: an infra error.
        env = worker.env
        check = FrameCheck(env)
        last = env.render_camera("corner2")
        check.check({"observation.images.corner2": last})
        env.reset(seed=instance.seed + 1, options={"instance": instance})
        check.new_episode()
        with pytest.raises(
            RenderError, match=r"camera corner2 returned the last frame it showed before the reset"
        ):
            check.check({"observation.images.corner2": last})
    finally:
        worker.close()
        if other is not None:
            other.close()


def test_a_dark_frame_that_is_not_constant_passes(env):
    """RoboView's scene lit at 3 % renders dark (every pixel ≤ 5 of 255) and passes; with the light at 0 it renders
    all 0 and does not."""
    from roboview.eval.running.frames import FrameCheck

    model, check = env.model, FrameCheck(env)
    env.reset(seed=3)
    head = model.vis.headlight
    arrays = (model.light_diffuse, model.light_specular, head.ambient, head.diffuse, head.specular)
    saved = [a.copy() for a in arrays]
    try:
        model.light_diffuse[:] *= 0.03
        for a in arrays[1:]:
            a[:] = 0
        dark = env.render_camera("front")
        assert dark.max() <= 5 and len(np.unique(dark.reshape(-1, 3), axis=0)) > 1
        check.check({"observation.images.front": dark})
        model.light_diffuse[:] = 0
        with pytest.raises(RenderError, match=r"camera front returned a constant frame \(all 0\)"):
            check.check({"observation.images.front": env.render_camera("front")})
    finally:
        for a, value in zip(arrays, saved, strict=True):
            a[:] = value


@pytest.mark.fast
def test_a_frame_is_constant_only_when_every_pixel_is_the_same_color():
    from roboview.eval.running.frames import constant_color, describe

    black = np.zeros((224, 224, 3), np.uint8)
    assert constant_color(black) == (0, 0, 0) and describe((0, 0, 0)) == "all 0"
    fog = np.broadcast_to(np.array([10, 20, 30], np.uint8), (256, 256, 3))  # one color, not contiguous
    assert constant_color(fog) == (10, 20, 30) and describe((10, 20, 30)) == "every pixel (10, 20, 30)"
    assert constant_color(np.full((64, 64), 7, np.uint8)) == (7,)
    dark = black.copy()
    dark[137, 59, 2] = 1  # one dim pixel
    assert constant_color(dark) is None
    red = np.zeros((224, 224, 3), np.uint8)
    red[:, :, 0] = 5  # every pixel (5, 0, 0): one color, though the channels differ
    assert constant_color(red) == (5, 0, 0)
    red[-1, -1] = (5, 0, 1)
    assert constant_color(red) is None


def test_a_worker_that_keeps_dying_becomes_an_infra_row_and_the_run_goes_on(tiny_benchmark):
    from roboview.eval.running.backends import run_local
    from roboview.eval.running.rollout import WorkerSpec, WorkItem

    works = [WorkItem(_item(tiny_benchmark), 0)]
    got = list(run_local(WorkerSpec(DyingConfig(), image_size=32, max_steps=3), works, 1, max_retries=1))
    assert [w.key for w, _ in got] == [works[0].key]
    row = got[0][1].row
    assert row["status"] == INFRA_ERROR and not row["success"] and row["policy"] is None
    assert "the worker died 2 times" in row["failure_reason"]
    assert row["instance_id"] == works[0].key[0] and row["repeat"] == 0


# -- re-run in the same run, and by the same command -------------------------------------------------------------


def test_infra_rows_run_again_after_the_pass_and_on_a_rerun_replacing_the_old_row(
    tiny_benchmark, tmp_path, monkeypatch, capsys
):
    from roboview.pipelines.evaluate import summary

    monkeypatch.setitem(PolicyConfig.get_known_choices(), "infra_once", OnceConfig)
    # Re-queued after the pass: the final table holds the re-run row only.
    out = tmp_path / "requeued"
    result = run(_cfg(tiny_benchmark, out, OnceConfig(marker=str(tmp_path / "a"))))
    journal = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert [r["status"] for r in journal] == [INFRA_ERROR, "ok", "ok"]
    lost = (journal[0]["instance_id"], journal[0]["repeat"])
    assert (journal[2]["instance_id"], journal[2]["repeat"]) == lost  # the infra one, run again
    rows = _rows(out)
    assert len(rows) == 2 and not rows.duplicated(["instance_id", "repeat"]).any()
    assert (rows["status"] == "ok").all() and result.infra_errors == 0 and result.new_episodes == 3

    # Not re-run in this run (max_infra_retries=0): the row stays infra_error, out of the success rate.
    out = tmp_path / "rerun"
    cfg = _cfg(tiny_benchmark, out, OnceConfig(marker=str(tmp_path / "b")), retries=0)
    first = run(cfg)
    rows = _rows(out)
    assert sorted(rows["status"]) == [INFRA_ERROR, "ok"] and first.infra_errors == 1 and first.episodes == 2
    summary(cfg, first)
    line = capsys.readouterr().out
    assert "1 ended by infrastructure errors" in line and "rerun the same command to re-run them" in line
    # The same command again: only the infra one runs, and its row replaces the old one.
    second = run(cfg)
    rows = _rows(out)
    assert second.new_episodes == 1 and second.infra_errors == 0 and (rows["status"] == "ok").all()
    assert len(rows) == 2 and not rows.duplicated(["instance_id", "repeat"]).any()
    assert len(read_journal(out)) == 2 and run(cfg).new_episodes == 0
    with pytest.raises(ValueError, match="max_infra_retries=-1 must be ≥ 0"):
        EvalConfig(max_infra_retries=-1)


def test_adaptive_decisions_never_see_infra_rows(tiny_benchmark, tmp_path, monkeypatch):
    import roboview.eval.statistics.adaptive as adaptive
    from roboview.eval.campaign.runner import run_rounds

    items = [_item(tiny_benchmark, "color", i) for i in range(4)]
    store = EpisodeStore(tmp_path / "ev", {"benchmark_version": "v", "policy": "still"})
    seen: list[tuple[int, list[dict]]] = []
    decide = adaptive.decide_split
    monkeypatch.setattr(
        adaptive, "decide_split", lambda rows, r, design: seen.append((r, rows)) or decide(rows, r, design)
    )
    ran: list[tuple[str, int]] = []

    def execute(works):
        for w in works:  # the first instance's episodes always end by infrastructure
            ran.append(w.key)
            store.add(
                {
                    **w.item.record,
                    "repeat": w.repeat,
                    "success": True,
                    "policy": "still",
                    "status": INFRA_ERROR if w.item is items[0] else "ok",
                }
            )

    class Bar:
        total = 100

        def refresh(self):
            pass

    cfg = EvaluateConfig(
        policy=policy_config("expert"),
        eval=EvalConfig(adaptive=True, max_repeats=3),
        output_dir=str(tmp_path / "ev"),
    )
    run_rounds(cfg, {"color": items}, {"color": 3}, {"color"}, store, execute, Bar())
    store.close()
    # After round r the decision sees 3 counted instances × r repeats: the infra one never enters it.
    assert [len(rows) for _, rows in seen] == [3 * r for r, _ in seen] and max(r for r, _ in seen) >= 2
    assert {row["instance_id"] for _, rows in seen for row in rows} == {
        i.record["instance_id"] for i in items[1:]
    }
    rounds = len({key[1] for key in ran})
    assert sum(key[0] == items[0].record["instance_id"] for key in ran) == rounds  # still run every round


# -- the report and the metrics leave them out -------------------------------------------------------------------


def test_metrics_and_report_leave_infra_rows_out_and_count_them(tmp_path):
    from roboview.pipelines.report import ReportConfig
    from roboview.pipelines.report import run as report
    from tests.helpers.episodes import make_episodes, write

    ok = make_episodes("expert", 0, splits=("color", "color_x_camera_pose"), repeats=3)
    ok = ok.assign(success=ok.index % 3 == 0, status="ok")  # SR 1/3
    color = ok[ok["split"] == "color"]
    first = ok.drop_duplicates("instance_id")  # one row per instance, run once more (repeat 3)
    infra = pd.concat(
        [first[first["split"] == "color"].head(4), first[first["split"] == "color_x_camera_pose"].head(2)]
    )
    infra = infra.assign(repeat=3)
    infra = infra.assign(success=True, status=INFRA_ERROR, failure_reason="lost the policy server")
    both = pd.concat([ok, infra], ignore_index=True)

    clean = compute_all_metrics(ok.drop(columns="status"), FAST)  # results written before `status`: all count
    mixed = compute_all_metrics(both, FAST)
    assert mixed["splits"]["color"]["sr"] == clean["splits"]["color"]["sr"] == color["success"].mean()
    assert mixed["splits"]["color"]["sr"] != both[both["split"] == "color"]["success"].mean()
    assert mixed["splits"]["color"]["n_episodes"] == len(color)
    assert mixed["splits"]["color"]["cv"] == clean["splits"]["color"]["cv"]
    assert (
        mixed["interactions"]["color_x_camera_pose"]["sr"]
        == clean["interactions"]["color_x_camera_pose"]["sr"]
    )
    assert (
        mixed["splits"]["color"]["n_infra_errors"],
        mixed["interactions"]["color_x_camera_pose"]["n_infra_errors"],
        mixed["n_infra_errors"],
        clean["splits"]["color"]["n_infra_errors"],
    ) == (4, 2, 6, 0)
    # Two policies: the paired comparisons pair counted episodes only.
    other = make_episodes("random", 1, splits=("color",), repeats=3).assign(status="ok")
    two_clean = compute_all_metrics(pd.concat([ok, other], ignore_index=True), FAST)
    two_mixed = compute_all_metrics(pd.concat([both, other], ignore_index=True), FAST)
    assert two_mixed["comparisons"] == two_clean["comparisons"]
    assert policy_layouts(two_mixed)["expert"]["n_infra_errors"] == 6

    result = report(
        ReportConfig(
            results=str(write(both, tmp_path / "episodes.parquet")),
            output_dir=str(tmp_path / "rep"),
            metrics=FAST,
            plots=False,
        )
    )
    assert result.metrics["splits"]["color"]["sr"] == color["success"].mean()
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "- expert, color: 4 episode(s) ended by infrastructure, not counted" in md
    assert "- expert, color_x_camera_pose: 2 episode(s) ended by infrastructure, not counted" in md
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "4 episode(s) ended by infrastructure, not counted" in html and 'id="infra"' in html
    report(
        ReportConfig(
            results=str(write(ok, tmp_path / "clean.parquet")),
            output_dir=str(tmp_path / "clean"),
            metrics=FAST,
            plots=False,
        )
    )
    assert "ended by infrastructure" not in (tmp_path / "clean" / "report.md").read_text()


# -- real servers killed mid-run and restarted -------------------------------------------------------------------


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _kill_and_restart_mid_run(cfg: EvaluateConfig, kill, restart) -> tuple[list, object]:
    """Run `cfg` in a thread; once its first episode is journalled, kill the server and start it again. Returns
    (errors the run raised, the restarted server)."""
    journal = Path(cfg.output_dir) / "episodes.jsonl"
    errors: list = []

    def go():
        try:
            run(cfg)
        except Exception as exc:  # noqa: BLE001  (the test reads it)
            errors.append(exc)

    thread = threading.Thread(target=go)
    thread.start()
    deadline = time.time() + 180
    while (
        time.time() < deadline
        and (not journal.exists() or not journal.read_text().strip())
        and thread.is_alive()
    ):
        time.sleep(0.02)
    kill()  # SIGKILL: no goodbye
    server = restart()
    thread.join(timeout=300)
    assert not thread.is_alive()
    return errors, server


def _check_interrupted_then_rerun(cfg: EvaluateConfig, errors: list, where: str, tmp_path: Path) -> None:
    from roboview.pipelines.report import ReportConfig
    from roboview.pipelines.report import run as report

    out = Path(cfg.output_dir)
    assert not errors, errors
    rows = _rows(out)
    # One worker, one connection: exactly the episode the kill cut short is infra_error, the rest the policy's.
    assert len(rows) == 4 and rows["status"].tolist().count(INFRA_ERROR) == 1, rows[
        ["status", "failure_reason"]
    ]
    lost = rows[rows["status"] == INFRA_ERROR].iloc[0]
    assert f"lost the {where}" in lost["failure_reason"] and "mid-episode" in lost["failure_reason"]
    assert (rows.loc[rows["status"] == "ok", "failure_reason"].str.contains("within 6 steps")).all()

    rep = report(
        ReportConfig(
            results=str(out / "episodes.parquet"), output_dir=str(tmp_path / "rep"), metrics=FAST, plots=False
        )
    )
    split = rep.metrics["splits"][lost["split"]]
    assert split["n_infra_errors"] == 1 and split["n_episodes"] == (rows["split"] == lost["split"]).sum() - 1
    assert (
        f"{lost['split']}: 1 episode(s) ended by infrastructure, not counted"
        in (tmp_path / "rep" / "report.md").read_text()
    )

    again = run(cfg)  # the same command, the server up: the infra one runs again and replaces its row
    rows = _rows(out)
    assert again.new_episodes == 1 and again.infra_errors == 0
    assert (
        len(rows) == 4
        and not rows.duplicated(["instance_id", "repeat"]).any()
        and (rows["status"] == "ok").all()
    )
    redone = rows[(rows["instance_id"] == lost["instance_id"]) & (rows["repeat"] == lost["repeat"])].iloc[0]
    assert (
        redone["episode_seed"] == lost["episode_seed"]
        and redone["steps"] == 6
        and "within 6" in redone["failure_reason"]
    )


def test_an_openpi_server_killed_and_restarted_mid_run(tiny_benchmark, tiny_checkpoint, tmp_path):
    from tests.helpers.servers import start_server, stop

    port = _free_port()
    server = start_server(tiny_checkpoint, port, "--server=openpi")
    servers = [server]
    policy = policy_config(
        "openpi",
        url=f"ws://127.0.0.1:{port}",
        cameras="left_top,wrist",
        image_size=64,
        reconnects=8,
        reconnect_backoff_s=0.25,
    )
    cfg = _cfg(tiny_benchmark, tmp_path / "ev", policy, splits="color,camera_pose", max_steps=6, retries=0)
    try:

        def restart():
            servers.append(start_server(tiny_checkpoint, port, "--server=openpi"))

        def kill():
            server.kill()
            server.wait()

        errors, _ = _kill_and_restart_mid_run(cfg, kill, restart)
        _check_interrupted_then_rerun(cfg, errors, f"openpi server ws://127.0.0.1:{port}", tmp_path)
    finally:
        for proc in servers:
            if proc.poll() is None:
                stop(proc)


def test_a_lerobot_policy_server_killed_and_restarted_mid_run(tiny_benchmark, tiny_checkpoint, tmp_path):
    port = _free_port()
    servers = [LeRobotServer(tmp_path, port, fresh=True)]
    policy = policy_config(
        "lerobot_async",
        server=servers[0].address,
        path=str(tiny_checkpoint),
        reconnects=8,
        reconnect_backoff_s=0.25,
    )
    cfg = _cfg(tiny_benchmark, tmp_path / "ev", policy, splits="color,camera_pose", max_steps=6, retries=0)
    try:
        errors, _ = _kill_and_restart_mid_run(
            cfg, servers[0].kill, lambda: servers.append(LeRobotServer(tmp_path, port, fresh=True))
        )
        _check_interrupted_then_rerun(cfg, errors, f"LeRobot policy server at 127.0.0.1:{port}", tmp_path)
    finally:
        for server in servers:
            server.stop()


@pytest.mark.fast
def test_an_interrupted_store_counts_the_episodes_on_disk(tmp_path):
    """A Ctrl-C can land inside `EpisodeStore.add`, between keeping a row and journalling it: what the interrupted
    message counts is the journal on disk (flushed first), what a rerun resumes from."""
    store = EpisodeStore(tmp_path / "ev", {"benchmark_version": "v", "policy": "still"})
    row = {"split": "color", "instance_id": "a", "repeat": 0, "success": True, "status": "ok"}
    store.add(row)
    store.rows[("b", 0)] = {**row, "instance_id": "b"}  # kept, the interrupt before its line was written
    store._journal.write(json.dumps({**row, "instance_id": "c"}) + "\n")  # written, not yet flushed
    assert len(store.rows) == 2 and store.saved() == 2
    assert [r["instance_id"] for r in read_journal(tmp_path / "ev")] == ["a", "c"]
