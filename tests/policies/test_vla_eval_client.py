"""vla_eval: RoboView's runner against vla-eval's own model servers (`vla_eval.model_servers.serve`) on 127.0.0.1.

The servers are vla-eval's: `serve_async` in a thread of this process (a `PredictModelServer` subclass declaring
specs and answering fixed actions, and vla-eval's `LeRobotModelServer` holding the tiny ACT checkpoint), or
`serve` in a subprocess where it must be killed.
"""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from vla_eval.model_servers.predict import PredictModelServer
from vla_eval.specs import (
    GRIPPER_CLOSE_01,
    GRIPPER_CLOSE_NEG,
    GRIPPER_CLOSE_POS,
    IMAGE_RGB,
    LANGUAGE,
    POSITION_ABSOLUTE,
    POSITION_DELTA,
    RAW,
    ROTATION_AA,
    ROTATION_EULER,
    STATE_EEF_POS_AA_GRIP,
    STATE_EEF_POS_QUAT_GRIP,
    STATE_JOINT,
    DimSpec,
)

from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, main, run
from roboview.policies.base import Episode
from roboview.policies.errors import InfraError, PolicyUnavailable
from roboview.policies.serving.vla_eval_specs import SpecMismatch
from roboview.policies.types import policy_config
from roboview.tasks.env import EE_STATE_KEY, STATE_KEY
from tests.helpers.evaluation import rows
from tests.helpers.servers import (
    POSE,
    fixed_server_class,
    free_port,
    joint_server,
    serving,
    start_vla_eval_server,
)

pytestmark = pytest.mark.slow
FixedServer = fixed_server_class()

ROOT = Path(__file__).resolve().parents[2]
ROW = ["instance_id", "repeat", "episode_seed", "success", "steps", "failure_reason"]
JOINTS = {"joints": DimSpec("joints", 7, "joint_positions"), "gripper": GRIPPER_CLOSE_01}


def evaluate(bench: Path, out: Path, policy, limit=2, max_steps=8):
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), "color"),
        policy,
        EvalConfig(n_repeats=1, limit=limit, num_workers=1, max_steps=max_steps, image_size=0),
        str(out),
    )
    return run(cfg)


def test_joint_server_negotiated_and_its_actions_reach_the_env(tiny_benchmark, tmp_path):
    from roboview.tasks import make_env

    server = joint_server()
    with serving(server) as url:
        out = tmp_path / "cli"
        main(
            [
                f"--benchmark.path={tiny_benchmark}",
                "--benchmark.splits=color",
                "--policy.type=vla_eval",
                f"--policy.url={url}",
                "--policy.image_size=64",
                "--eval.n_repeats=1",
                "--eval.limit=2",
                "--eval.max_steps=6",
                "--eval.num_workers=1",
                f"--output_dir={out}",
            ]
        )
        got = rows(out)
        assert got["policy"].tolist() == ["vla_eval:FixedServer"] * 2 and got["steps"].tolist() == [6, 6]
        assert (got["status"] == "ok").all() and not got["success"].any()
        # One EPISODE_START per episode with its instruction and seed; one OBSERVATION per step, as negotiated.
        assert sorted(s["seed"] for s in server.starts) == sorted(got["episode_seed"].tolist())
        assert all(s["name"] and s["task"] == "pick_place" for s in server.starts)
        assert len(server.seen) == 12
        first = server.seen[0]
        assert set(first["images"]) == {"front"} and first["images"]["front"].shape == (64, 64, 3)
        assert first["states"].shape == (8,) and first["task_description"] == server.starts[0]["name"]

        # The commanded pose reaches the env: the joints settle on it, the gripper closes.
        config = policy_config("vla_eval", url=url, image_size=64)
        assert (config.env_control(), config.observed_cameras(), config.negotiated.state_key) == (
            "joint",
            ("front",),
            STATE_KEY,
        )
        env = make_env(cameras=config.observed_cameras(), image_size=64, max_steps=60)
        policy = config.build(None)
        try:
            obs, _ = env.reset(seed=3)
            policy.reset(Episode.of(env, 3))
            for _ in range(40):
                action = policy.select_action(obs)
                obs, *_ = env.step(action)
            np.testing.assert_array_equal(action, POSE)
            np.testing.assert_allclose(obs[STATE_KEY][:7], POSE[:7], atol=0.03)
            assert obs[STATE_KEY][7] > 0.5
        finally:
            policy.close()
            env.close()


def test_lerobot_model_server_gives_the_in_process_rows_and_actions(
    tiny_benchmark, tiny_checkpoint, tmp_path
):
    from vla_eval.model_servers.lerobot import LeRobotModelServer

    from roboview.benchmark.format import load_benchmark
    from roboview.policies.lerobot_policy import LeRobotPolicy
    from roboview.tasks import make_env

    model = LeRobotModelServer("act", str(tiny_checkpoint), device="cpu")
    with serving(model) as url:
        config = policy_config("vla_eval", url=url, image_size=64, cameras="left_top,wrist")
        assert config.env_control() == "joint" and config.negotiated.state_key == STATE_KEY
        # 25 steps: three model calls (the checkpoint's n_action_steps = 10), two answered chunks between.
        lerobot = policy_config("lerobot", path=str(tiny_checkpoint))
        local = evaluate(tiny_benchmark, tmp_path / "local", lerobot, max_steps=25)
        served = evaluate(tiny_benchmark, tmp_path / "served", config, max_steps=25)
        assert local.episodes == served.episodes == 2
        pd.testing.assert_frame_equal(rows(tmp_path / "local")[ROW], rows(tmp_path / "served")[ROW])
        # Images only on the steps that run the model: the same rows.
        chunked = policy_config("vla_eval", url=url, image_size=64, cameras="left_top,wrist", images_every=10)
        evaluate(tiny_benchmark, tmp_path / "chunked", chunked, max_steps=25)
        pd.testing.assert_frame_equal(rows(tmp_path / "local")[ROW], rows(tmp_path / "chunked")[ROW])
        assert list(rows(tmp_path / "chunked")["steps"]) == [25, 25]

        # The 2-step checkpoint's rows all end at max_steps: compare the actions too, across a chunk boundary.
        items = load_benchmark(tiny_benchmark, ["color"]).splits["color"][:2]
        env = make_env(cameras=config.observed_cameras(), image_size=64)
        policy, reference = config.build(None), LeRobotPolicy(str(tiny_checkpoint), "cpu")
        try:
            for seed, item in enumerate(items):
                obs, _ = env.reset(seed=seed, options={"instance": item.instance})
                policy.reset(Episode.of(env, seed))
                reference.reset(Episode.of(env, seed))
                for _ in range(12):
                    want = reference.select_action(obs)
                    np.testing.assert_allclose(policy.select_action(obs), want, rtol=0, atol=1e-5)
                    obs, *_ = env.step(want)
        finally:
            policy.close()
            env.close()


def test_a_model_that_raises_fails_its_episode_with_the_servers_message(tiny_benchmark, tmp_path):
    with serving(joint_server(fail_at=2)) as url:
        result = evaluate(
            tiny_benchmark, tmp_path / "out", policy_config("vla_eval", url=url, image_size=64), limit=1
        )
    got = rows(tmp_path / "out")
    assert result.episodes == 1 and got["status"].tolist() == ["ok"] and got["steps"].tolist() == [2]
    reason = got["failure_reason"][0]
    assert "ServerError" in reason and "observation_failed: RuntimeError: model exploded at step 2" in reason


def test_a_server_killed_mid_episode_is_an_infra_error_and_one_gone_stops_the_run():
    port = free_port()
    proc = start_vla_eval_server(port)
    try:
        config = policy_config(
            "vla_eval", url=f"ws://127.0.0.1:{port}", image_size=64, reconnects=1, reconnect_backoff_s=0.1
        )
        policy = config.build(None)
        obs = {
            "observation.images.front": np.zeros((64, 64, 3), np.uint8),
            STATE_KEY: np.zeros(8, np.float32),
        }
        episode = Episode("pick_place", "pick up the cube", 7, {}, 64)
        policy.reset(episode)
        np.testing.assert_array_equal(policy.select_action(obs), POSE)
        proc.kill()
        proc.wait()
        proc = start_vla_eval_server(port)  # back, but the episode's server state is gone
        with pytest.raises(InfraError, match=r"lost the vla-eval server .* mid-episode"):
            policy.select_action(obs)
        np.testing.assert_array_equal(policy.select_action(obs), POSE)  # the reopened connection works
        proc.kill()
        proc.wait()
        with pytest.raises(PolicyUnavailable, match=rf"ws://127.0.0.1:{port} is unreachable.*rerun the same"):
            policy.select_action(obs)
        policy.close()
    finally:
        proc.kill()
        proc.wait()


def test_unmappable_specs_stop_before_any_episode_naming_the_field(tiny_benchmark, tmp_path, capsys):
    euler = FixedServer(
        np.zeros(7),
        {"position": POSITION_DELTA, "rotation": ROTATION_EULER, "gripper": GRIPPER_CLOSE_POS},
        {},
    )
    with serving(euler) as url:
        out = tmp_path / "out"
        with pytest.raises(SystemExit) as exit_:
            main(
                [
                    f"--benchmark.path={tiny_benchmark}",
                    "--policy.type=vla_eval",
                    f"--policy.url={url}",
                    f"--output_dir={out}",
                ]
            )
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and not out.exists() and euler.seen == []
        assert (
            "action_spec['rotation']: it declares format 'euler_xyz' (3 dims); RoboView provides axis_angle"
            in err
        )
    quat = FixedServer(POSE, JOINTS, {"front": IMAGE_RGB, "state": STATE_EEF_POS_QUAT_GRIP})
    with (
        serving(quat) as url,
        pytest.raises(SpecMismatch, match=r"observation_spec\['state'\].*eef_pos3_quat4_gripper1"),
    ):
        policy_config("vla_eval", url=url)
    other_cams = FixedServer(POSE, JOINTS, {"exterior": IMAGE_RGB, "state": STATE_JOINT})
    with serving(other_cams) as url:
        with pytest.raises(
            SpecMismatch,
            match=r"'exterior'.*front, left_top, right_top, wrist, agentview.*--policy.camera_map=exterior",
        ):
            policy_config("vla_eval", url=url)
        assert policy_config("vla_eval", url=url, camera_map="exterior=right_top").negotiated.cameras == (
            ("exterior", "right_top"),
        )
    # LIBERO's camera names negotiate (LIBERO's envs render them); RoboView's scene refuses them before any episode.
    libero_cams = FixedServer(POSE, JOINTS, {"agentview": IMAGE_RGB, "state": STATE_JOINT})
    with serving(libero_cams) as url:
        from roboview.policies.fit import fit_policy

        with pytest.raises(
            ValueError, match="observes camera.s. agentview, which the 'pick_place' task's env"
        ):
            fit_policy(policy_config("vla_eval", url=url), ["pick_place"])
    wrist = FixedServer(
        POSE, {"actions": RAW}, {"image": IMAGE_RGB, "state": RAW}, {"send_wrist_image": True}
    )
    with (
        serving(wrist) as url,
        pytest.raises(SpecMismatch, match=r"send_wrist_image.*add wrist to --policy.cameras"),
    ):
        policy_config("vla_eval", url=url, cameras="front")


LIBERO_OBS = {
    "agentview": IMAGE_RGB,
    "wrist": IMAGE_RGB,
    "state": STATE_EEF_POS_AA_GRIP,
    "language": LANGUAGE,
}


@pytest.mark.parametrize(
    ("position", "gripper", "control", "want_gripper"),
    [
        (POSITION_DELTA, GRIPPER_CLOSE_POS, "ee_delta", 1.0),  # LIBERO's convention: +1 close
        (POSITION_ABSOLUTE, GRIPPER_CLOSE_NEG, "ee_abs", -1.0),  # +0.7 under close-negative: open
    ],
)
def test_end_effector_specs_negotiate_an_ee_control_and_send_the_ee_state(
    position, gripper, control, want_gripper
):
    answer = np.array([0.1, -0.2, 0.3, 0.0, 0.5, -0.1, 0.7], np.float32)
    server = FixedServer(
        answer, {"position": position, "rotation": ROTATION_AA, "gripper": gripper}, LIBERO_OBS
    )
    with serving(server) as url:
        config = policy_config(
            "vla_eval", url=url, camera_map="agentview=left_top,wrist=wrist", image_size=32
        )
        assert config.env_control() == control and config.negotiated.state_key == EE_STATE_KEY
        assert config.observed_cameras() == ("left_top", "wrist")
        with pytest.raises(SpecMismatch, match=rf"\({control} control\).*--policy.control=joint"):
            policy_config("vla_eval", url=url, camera_map="agentview=left_top", control="joint")
        # An observation as an EE env gives it (not stepped here): the EE state goes out as the state.
        ee_state = np.arange(8, dtype=np.float32) / 10
        obs = {
            "observation.images.left_top": np.full((32, 32, 3), 1, np.uint8),
            "observation.images.wrist": np.full((32, 32, 3), 2, np.uint8),
            STATE_KEY: np.zeros(8, np.float32),
            EE_STATE_KEY: ee_state,
        }
        policy = config.build(None)
        policy.reset(Episode("pick_place", "put the cube in the bowl", 11, {}, 32))
        action = policy.select_action(obs)
        policy.close()
    np.testing.assert_array_equal(action, [*answer[:6], want_gripper])
    seen = server.seen[0]
    np.testing.assert_array_equal(seen["states"], ee_state)
    assert (seen["images"]["agentview"] == 1).all() and (seen["images"]["wrist"] == 2).all()
    assert server.starts == [
        {
            "name": "put the cube in the bowl",
            "instruction": "put the cube in the bowl",
            "task": "pick_place",
            "seed": 11,
            "image_size": 32,
        }
    ]


def test_lockstep_envs_are_batched_by_a_batching_server():
    """Three slots, one connection each, every observation sent before any answer is read: while the server's
    first batch runs the others queue, and its next batch holds two."""
    server = joint_server(max_batch_size=2)
    with serving(server) as url:
        policy = policy_config("vla_eval", url=url, image_size=16).build_batched(None, 3)
        for slot in range(3):
            policy.reset(Episode("pick_place", f"task {slot}", slot, {}, 16), slot)
        obs = {
            "observation.images.front": np.zeros((16, 16, 3), np.uint8),
            STATE_KEY: np.zeros(8, np.float32),
        }
        got = policy.select_actions({0: obs, 1: obs, 2: obs})
        policy.close()
    assert set(got) == {0, 1, 2} and all((a == POSE).all() for a in got.values())
    assert sorted(server.batches) == [1, 2]
    assert sorted(o["task_description"] for o in server.seen) == ["task 0", "task 1", "task 2"]


class ExpertReplayServer(PredictModelServer):
    """LIBERO's conventions — position and axis-angle deltas, gripper +1 = close, the end-effector state in —
    answering the scripted expert's `ee_delta` actions recorded for the episode's seed."""

    def __init__(self, actions_by_seed: dict[int, list[np.ndarray]]) -> None:
        super().__init__()
        self.actions, self.queues, self.states = actions_by_seed, {}, []

    def get_action_spec(self):
        return {"position": POSITION_DELTA, "rotation": ROTATION_AA, "gripper": GRIPPER_CLOSE_POS}

    def get_observation_spec(self):
        return {"front": IMAGE_RGB, "state": STATE_EEF_POS_AA_GRIP, "language": LANGUAGE}

    def get_observation_params(self):
        return {"send_state": True}

    async def on_episode_start(self, config, ctx):
        self.queues[ctx.session_id] = list(self.actions[config["task"]["seed"]])
        await super().on_episode_start(config, ctx)

    def predict(self, obs, ctx):
        self.states.append(np.asarray(obs["state"], np.float64))
        queue = self.queues[ctx.session_id]
        return {"actions": queue.pop(0) if len(queue) > 1 else queue[0]}


def test_a_libero_convention_server_drives_the_end_effector_as_the_native_expert_does(
    tiny_benchmark, tmp_path
):
    """End to end in end-effector control: a server declaring LIBERO's specs is negotiated to `ee_delta`, sent the EE
    state, and its actions (the expert's, replayed) give exactly the rows of the expert run natively in ee_delta."""
    from roboview.benchmark.format import load_benchmark
    from roboview.tasks import load_task, make_env
    from roboview.variation.instances import episode_seed

    split, max_steps = "color_x_camera_pose", 60  # one context: every instance of a repeat shares its seed
    env = make_env(cameras=("front",), image_size=64, max_steps=max_steps, lazy=True, control="ee_delta")
    by_seed: dict[int, list[np.ndarray]] = {}
    for item in load_benchmark(tiny_benchmark, [split]).splits[split]:
        seed = episode_seed(item.record["context_id"], 0)
        env.reset(seed=seed, options={"instance": item.instance})
        expert = load_task(item.instance.task).make_expert(env)
        expert.reset()
        actions, done = [], False
        while not done:
            actions.append(np.asarray(expert.select_action(None), np.float32))
            _, _, success, truncated, _ = env.step(actions[-1])
            done = success or truncated
        if seed in by_seed:  # the expert reads the state only: the visual factors leave its actions alone
            assert len(actions) == len(by_seed[seed]) and all(map(np.array_equal, actions, by_seed[seed]))
        by_seed[seed] = actions
    env.close()
    assert len(by_seed) == 1 and all(np.all(np.abs(a) <= 1) for a in by_seed[seed])

    def run_split(policy, out):
        return run(
            EvaluateConfig(
                BenchmarkConfig(str(tiny_benchmark), split),
                policy,
                EvalConfig(n_repeats=1, num_workers=1, max_steps=max_steps, image_size=64),
                str(out),
            )
        )

    server = ExpertReplayServer(by_seed)
    with serving(server) as url:
        config = policy_config("vla_eval", url=url, cameras="front", image_size=64)
        assert config.env_control() == "ee_delta" and config.negotiated.state_key == EE_STATE_KEY
        run_split(config, tmp_path / "served")
    run_split(policy_config("expert", control="ee_delta"), tmp_path / "native")
    served, native = rows(tmp_path / "served"), rows(tmp_path / "native")
    assert len(served) == 6 and served["success"].all()
    pd.testing.assert_frame_equal(served[ROW], native[ROW])
    # The server was sent the EE state: the pinch point's position (m), axis-angle, two finger openings.
    assert all(s.shape == (8,) for s in server.states) and 0.0 < server.states[0][2] < 1.0
    assert json.loads((tmp_path / "served" / "run.json").read_text())["control"] == "ee_delta"


def test_images_go_only_on_the_steps_that_run_the_model(tiny_benchmark, tmp_path):
    server = joint_server()
    with serving(server) as url:
        evaluate(
            tiny_benchmark,
            tmp_path / "ev",
            policy_config("vla_eval", url=url, cameras="front", image_size=64, images_every=3),
            limit=1,
            max_steps=7,
        )
    assert [("images" in obs) for obs in server.seen] == [True, False, False, True, False, False, True]
    assert all("state" in obs for obs in server.seen)
    with pytest.raises(ValueError, match=r"--policy.images_every=0 must be 1 or more"):
        policy_config("vla_eval", url="ws://127.0.0.1:9", images_every=0)


def test_a_raw_server_whose_model_acts_in_another_control_stops_before_any_episode(tiny_benchmark, tmp_path):
    """LeRobot's server declares a `raw` action spec; its end-effector model answers 7 values. Without
    --policy.control the run stops at the pre-flight step, naming the flag, and writes no episode; with it, it runs."""
    from vla_eval.specs import RAW

    ee_action = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0], np.float32)
    server = FixedServer(ee_action, {"actions": RAW}, {"image": IMAGE_RGB, "language": LANGUAGE})
    with serving(server) as url:
        with pytest.raises(ValueError) as err:
            evaluate(
                tiny_benchmark,
                tmp_path / "wrong",
                policy_config("vla_eval", url=url, cameras="front", image_size=64),
            )
        message = str(err.value)
        assert message.startswith("pre-flight: one step of") and "answered an action of 7 values" in message
        assert "pass --policy.control=ee_delta or --policy.control=ee_abs" in message
        assert not (tmp_path / "wrong" / "episodes.jsonl").exists()
        result = evaluate(
            tiny_benchmark,
            tmp_path / "right",
            policy_config("vla_eval", url=url, cameras="front", image_size=64, control="ee_delta"),
        )
    assert result.episodes == 2 and rows(tmp_path / "right")["status"].eq("ok").all()
