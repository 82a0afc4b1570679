"""A LIBERO checkpoint on every path, on LIBERO's own scenes.

Demos collected by `roboview-collect` in the layout of LeRobot's LIBERO datasets (`observation.images.image`,
`image2`, 8-d `observation.state`, 7-d OSC_POSE delta `action`) load with `LeRobotDataset` and replay bit for bit;
an ACT trained on them by `roboview-train` runs in-process (`--policy.type=lerobot`, its control and cameras read
from the checkpoint) and behind openpi's websocket protocol (`--policy.obs_format=libero`) with the same trajectory;
what the openpi client hands a server on LIBERO's scenes is what openpi's LIBERO example hands it (flipped, 256²
brought to 224² by openpi-client's resize_with_pad, LIBERO's 8-d state).
"""

import asyncio
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from roboview.benchmark.format import BenchmarkItem
from roboview.libero.task import baseline_libero_instance
from roboview.policies.fit import fit_policy
from roboview.policies.types import policy_config
from tests.helpers import cli

pytestmark = pytest.mark.slow
REPO = "t/libero_demos"
LAYOUT = {"observation.images.image", "observation.images.image2", "observation.state", "action"}


@pytest.fixture(scope="module")
def libero_demos(tmp_path_factory) -> Path:
    """One expert demo of libero_object/0 at 64², collected in LeRobot's LIBERO layout."""
    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    root = tmp_path_factory.mktemp("libero") / "ds"
    dataset = DatasetConfig(
        repo_id=REPO,
        root=str(root),
        num_episodes=1,
        image_size=64,
        cameras=["image", "image2"],
        task="libero",
        control="ee_delta",
        contexts="libero_task=libero_object/0",
    )
    result = collect(CollectConfig(dataset, num_workers=1, max_steps=280))
    assert result.episodes == 1 and result.failures == 0
    return root


@pytest.fixture(scope="module")
def libero_checkpoint(libero_demos, tmp_path_factory) -> Path:
    """A 2-step ACT trained on the LIBERO demos by roboview-train (LeRobot's trainer)."""
    out = tmp_path_factory.mktemp("libero_train") / "train"
    proc = cli.run(
        "roboview.pipelines.train",
        f"--dataset.repo_id={REPO}",
        f"--dataset.root={libero_demos}",
        f"--output_dir={out}",
        "--batch_size=2",
        "--steps=2",
        "--save_freq=2",
        "--device=cpu",
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out / "checkpoints" / "last" / "pretrained_model"


def test_libero_demos_are_in_lerobots_libero_layout_and_replay_bit_for_bit(libero_demos):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from roboview.demos.recorder import training_instance
    from roboview.tasks import make_env

    dataset = LeRobotDataset(REPO, root=libero_demos)
    features = dataset.meta.features
    assert LAYOUT <= set(features) and dataset.meta.robot_type == "panda"
    assert features["observation.state"]["names"] == {
        "motors": ["x", "y", "z", "roll", "pitch", "yaw", "gripper", "gripper"]
    }
    assert tuple(features["observation.images.image"]["shape"]) == (64, 64, 3)
    frames = dataset.hf_dataset.with_format("numpy")[:]
    states, actions = np.stack(frames["observation.state"]), np.stack(frames["action"])
    assert actions.shape[1] == 7 and set(np.unique(actions[:, 6])) <= {-1.0, 1.0}
    sample = dataset[0]
    assert sample["task"] == "pick up the alphabet soup and place it in the basket"
    assert tuple(sample["observation.images.image2"].shape) == (3, 64, 64)

    # Replay: the episode's seed and context, the recorded actions → the recorded states, and LIBERO's success.
    import pandas as pd

    provenance = pd.read_parquet(libero_demos / "meta" / "roboview" / "episodes.parquet").iloc[0]
    seed = int(provenance["episode_seed"])
    instance = training_instance(np.random.default_rng(seed), "libero", {"libero_task": ("libero_object/0",)})
    assert instance.instance_id == provenance["instance_id"]
    env = make_env("libero", cameras=("image",), image_size=64, control="ee_delta")
    try:
        obs, _ = env.reset(seed=seed, options={"instance": instance})
        replayed, success = [], False
        for action in actions:
            replayed.append(obs["observation.state"])
            obs, _, success, _, _ = env.step(action)
        np.testing.assert_array_equal(np.stack(replayed), states)
        assert success
    finally:
        env.close()


def test_a_libero_checkpoint_fits_libero_and_is_refused_elsewhere(libero_checkpoint):
    config = policy_config("lerobot", path=str(libero_checkpoint), device="cpu")
    # Its control from its dataset's LIBERO action names, its cameras LeRobot's LIBERO names.
    assert config.env_control() == "ee_delta"
    assert config.observed_cameras() == ("image", "image2") and config.input_image_size() == 64
    fit_policy(config, ["libero"])
    with pytest.raises(
        ValueError, match="observes camera.s. image, image2, which the 'pick_place' task's env"
    ):
        fit_policy(config, ["pick_place"])
    # Without its dataset the 7-d checkpoint's control stays open until LIBERO's envs settle it.
    blind = libero_checkpoint.parent / "blind"
    if not blind.exists():
        import shutil

        shutil.copytree(libero_checkpoint, blind)
        (blind / "train_config.json").unlink()
    open_config = policy_config("lerobot", path=str(blind), device="cpu")
    with pytest.raises(ValueError, match="pass --policy.control=ee_delta or --policy.control=ee_abs"):
        open_config.env_control()
    fit_policy(open_config, ["libero"])
    assert open_config.env_control() == "ee_delta"


def _episode(policy, steps: int = 6):
    """One LIBERO episode (libero_object/0, init state 1) of `policy` in an evaluation worker: its row and the
    end effector's path."""
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem

    instance = baseline_libero_instance("libero_object/0", "1")
    worker = EvalWorker(WorkerSpec(policy, image_size=64, max_steps=steps, record_media=True, task="libero"))
    try:
        result = worker.run(WorkItem(BenchmarkItem(instance, instance.to_record()), 0))
    finally:
        worker.close()
    return result.row, result.ee_path


@pytest.fixture(scope="module")
def in_process(libero_checkpoint):
    """The checkpoint's episode run in-process: the row and path every served path must give."""
    return _episode(policy_config("lerobot", path=str(libero_checkpoint), device="cpu"))


def test_the_checkpoint_served_over_openpi_gives_the_in_process_episode(libero_checkpoint, in_process):
    from tests.helpers.servers import free_port, start_server, stop

    port = free_port()
    server = start_server(libero_checkpoint, port, "--server=openpi", "--obs_format=libero", "--task=libero")
    try:
        client = policy_config(
            "openpi",
            url=f"ws://127.0.0.1:{port}",
            obs_format="libero",
            cameras="agentview,wrist",
            image_size=64,
            render_size=64,
            control="ee_delta",
        )
        served_row, served_path = _episode(client)
    finally:
        stop(server)
    local_row, local_path = in_process
    assert served_row["status"] == local_row["status"] == "ok"
    for key in ("instance_id", "episode_seed", "success", "steps"):
        assert served_row[key] == local_row[key], key
    np.testing.assert_allclose(served_path, local_path, rtol=0, atol=1e-6)
    assert len(local_path) == 6 and np.ptp(local_path, axis=0).max() > 1e-4  # the arm moved


def test_the_openpi_client_sends_what_openpis_libero_example_sends():
    """openpi-server's own server records the requests; the reference is openpi's LIBERO example's preprocessing
    of the raw LIBERO observation (flip, resize_with_pad to 224, the 8-d EEF state)."""
    from openpi_client.image_tools import resize_with_pad
    from openpi_server.websocket_policy_server import WebsocketPolicyServer

    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.libero.env import lerobot_state
    from tests.helpers.servers import free_port

    class Recording:
        def __init__(self) -> None:
            self.requests = []

        def infer(self, obs: dict) -> dict:
            self.requests.append(obs)
            return {"actions": np.zeros((5, 7), np.float32)}

        def reset(self) -> None:
            pass

    port, recording = free_port(), Recording()
    server = WebsocketPolicyServer(recording, "127.0.0.1", port, {"policy": "recording"})
    threading.Thread(target=server.serve_forever, daemon=True).start()
    client = policy_config(
        "openpi",
        url=f"ws://127.0.0.1:{port}",
        obs_format="libero",
        cameras="agentview,wrist",
        control="ee_delta",
    )
    assert client.input_image_size() == 256 and client.image_size == 224
    instance = baseline_libero_instance("libero_object/0", "1")
    worker = EvalWorker(WorkerSpec(client, image_size=256, max_steps=1, task="libero"))
    try:
        row = worker.run(WorkItem(BenchmarkItem(instance, instance.to_record()), 0)).row
        # The raw LIBERO observation of that episode's reset: its world reset again with the episode's seed.
        raw = worker.env.libero_world.reset(seed=int(row["episode_seed"]))
        expected = {
            key: resize_with_pad(np.ascontiguousarray(raw[f"{camera}_image"][::-1, ::-1]), 224, 224)
            for key, camera in (("image", "agentview"), ("wrist", "robot0_eye_in_hand"))
        }
        expected_state = lerobot_state(raw)
    finally:
        worker.close()
    (request,) = recording.requests
    assert set(request) == {"observation/image", "observation/wrist_image", "observation/state", "prompt"}
    expected_image, expected_wrist = expected["image"], expected["wrist"]
    assert expected_image.shape == (224, 224, 3)
    np.testing.assert_array_equal(request["observation/image"], expected_image)
    np.testing.assert_array_equal(request["observation/wrist_image"], expected_wrist)
    np.testing.assert_array_equal(request["observation/state"], expected_state)
    assert request["prompt"] == "pick up the alphabet soup and place it in the basket"
    assert json.dumps(client.served_by()["metadata"])  # recorded as provenance


def test_the_checkpoint_behind_vla_evals_lerobot_server_gives_the_in_process_episode(
    libero_checkpoint, in_process
):
    """vla-eval's own LeRobotModelServer holding the checkpoint, LIBERO's cameras mapped onto its features."""
    from vla_eval.model_servers.lerobot import LeRobotModelServer

    from tests.helpers.servers import serving

    model = LeRobotModelServer(
        "act", str(libero_checkpoint), device="cpu", image_keys={"agentview": "image", "wrist": "image2"}
    )
    with serving(model) as url:
        client = policy_config(
            "vla_eval", url=url, image_size=64, cameras="agentview,wrist", control="ee_delta"
        )
        assert client.env_control() == "ee_delta" and client.observed_cameras() == ("agentview", "wrist")
        fit_policy(client, ["libero"])
        served_row, served_path = _episode(client)
    local_row, local_path = in_process
    assert served_row["status"] == local_row["status"] == "ok"
    for key in ("instance_id", "episode_seed", "success", "steps"):
        assert served_row[key] == local_row[key], key
    np.testing.assert_allclose(served_path, local_path, rtol=0, atol=1e-6)


def test_the_vla_eval_client_sends_what_vla_evals_libero_benchmark_sends():
    """A server declaring what vla-eval's LIBERO benchmark declares is sent, step for step, what that benchmark's
    own `make_obs` builds from its own env (same init state, seed and actions: images, state, instruction), and
    its actions reach the env as that benchmark steps them (gripper discretized by its sign)."""
    from vla_eval.benchmarks.libero.benchmark import LIBEROBenchmark

    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from tests.helpers.servers import fixed_server_class, serving

    FixedServer = fixed_server_class()

    # Continuous gripper values: vla-eval's LIBERO benchmark sends their sign to the env.
    actions = [
        np.array([0.4, -0.2, 0.1, 0.0, 0.1, 0.0, -0.3], np.float32),
        np.array([0.0, 0.5, -0.3, 0.2, 0.0, 0.0, 0.6], np.float32),
        np.array([-0.3, 0.1, 0.2, 0.0, -0.1, 0.1, 0.2], np.float32),
    ]

    class Replaying(FixedServer):
        def predict_batch(self, obs_batch, ctx_batch):
            self.seen.extend(obs_batch)
            return [{"actions": actions[min(ctx.step, len(actions) - 1)].copy()} for ctx in ctx_batch]

    spec = LIBEROBenchmark("libero_object", send_wrist_image=True, send_state=True)
    server = Replaying(
        actions[0],
        spec.get_action_spec(),
        spec.get_observation_spec(),
        {"send_state": True, "send_wrist_image": True},
    )
    instance = baseline_libero_instance("libero_object/0", "1")
    with serving(server) as url:
        client = policy_config("vla_eval", url=url)
        assert client.env_control() == "ee_delta" and client.observed_cameras() == ("agentview", "wrist")
        assert client.input_image_size() == 256  # vla-eval's LIBERO side, by default
        worker = EvalWorker(WorkerSpec(client, image_size=256, max_steps=len(actions), task="libero"))
        try:
            row = worker.run(WorkItem(BenchmarkItem(instance, instance.to_record()), 0)).row
        finally:
            worker.close()
    assert row["status"] == "ok" and row["steps"] == len(actions)

    seed = int(row["episode_seed"])
    reference = LIBEROBenchmark("libero_object", seed=seed, send_wrist_image=True, send_state=True)
    task = {**reference.get_tasks()[0], "episode_idx": 1}

    async def benchmark_episode() -> list[dict]:
        """vla-eval's own episode loop of the benchmark: start, then observation / action per step."""
        sent = []
        await reference.start_episode(task)
        for action in actions:
            sent.append(await reference.get_observation())
            await reference.apply_action({"actions": action})
        return sent

    try:
        expected_steps = asyncio.run(benchmark_episode())
    finally:
        reference.cleanup()
    for step, (expected, got) in enumerate(zip(expected_steps, server.seen, strict=True)):
        assert got["task_description"] == expected["task_description"] == task["name"], step
        for camera in ("agentview", "wrist"):
            np.testing.assert_array_equal(
                got["images"][camera], expected["images"][camera], err_msg=f"{step}"
            )
        assert got["states"].dtype == expected["states"].dtype == np.float64
        np.testing.assert_array_equal(got["states"], expected["states"], err_msg=f"{step}")
    assert expected_steps[0]["images"]["agentview"].shape == (256, 256, 3)


def test_libero_states_follow_vla_evals_quaternion_conventions():
    """Both axis-angle conventions of vla-eval's LIBERO benchmark (antipodal-normalized by default, robosuite's under
    `quat_no_antipodal`), on quaternions with w < 0 where they differ; the reference runs in its own process (importing
    vla-eval's LIBERO benchmark switches rendering to EGL)."""
    from roboview.policies.serving.vla_eval_specs import libero_state

    rng = np.random.default_rng(0)
    quats = rng.normal(size=(6, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    quats[:, 3] = -np.abs(quats[:, 3])
    proprios = [np.concatenate([rng.normal(size=3), q, rng.normal(size=2)]) for q in quats]
    code = (
        "import json, sys, numpy as np\n"
        "from vla_eval.benchmarks.libero.benchmark import LIBEROBenchmark\n"
        "out = []\n"
        "for p in json.load(sys.stdin):\n"
        "    obs = dict(robot0_eef_pos=np.array(p[:3]), robot0_eef_quat=np.array(p[3:7]),"
        " robot0_gripper_qpos=np.array(p[7:]))\n"
        "    out.append([LIBEROBenchmark(quat_no_antipodal=f)._proprio_state(obs).tolist() for f in (False, True)])\n"
        "print(json.dumps(out))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        input=json.dumps([p.tolist() for p in proprios]),
        capture_output=True,
        text=True,
        check=True,
    )
    for proprio, (default, robosuite) in zip(proprios, json.loads(proc.stdout), strict=True):
        np.testing.assert_array_equal(libero_state(proprio, no_antipodal=False), default)
        np.testing.assert_array_equal(libero_state(proprio, no_antipodal=True), robosuite)
        assert not np.allclose(default[3:6], robosuite[3:6])  # w < 0: the conventions differ
