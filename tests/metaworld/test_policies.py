"""A Meta-World checkpoint on RoboView's Meta-World scenes.

Demos collected by `roboview-collect` in the layout of LeRobot's Meta-World datasets (`observation.image`, 4-d
`observation.state` and `action`, 80 fps) load with `LeRobotDataset` and replay bit for bit; an ACT trained on them
by `roboview-train` is evaluated in-process by `roboview-evaluate` (its control, camera and image size read from the
checkpoint) and the results verify; a checkpoint that is not Meta-World's is refused before any episode.
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("metaworld", reason="Meta-World not installed (make install-metaworld)")

from roboview.policies.fit import fit_policy  # noqa: E402
from roboview.policies.types import policy_config  # noqa: E402
from tests.helpers import cli

pytestmark = pytest.mark.slow
REPO = "t/metaworld_demos"


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    """Two expert demos of push-v3 at 64², collected in LeRobot's Meta-World layout."""
    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    root = tmp_path_factory.mktemp("metaworld") / "ds"
    dataset = DatasetConfig(
        repo_id=REPO, root=str(root), num_episodes=2, image_size=64, cameras=["top"], task="metaworld"
    )
    result = collect(CollectConfig(dataset, num_workers=1))
    assert result.episodes == 2 and result.failures == 0
    return root


@pytest.fixture(scope="module")
def checkpoint(demos, tmp_path_factory) -> Path:
    """A 2-step ACT trained on the demos by roboview-train (LeRobot's trainer)."""
    out = tmp_path_factory.mktemp("metaworld_train") / "train"
    args = [f"--dataset.repo_id={REPO}", f"--dataset.root={demos}", f"--output_dir={out}"]
    args += ["--batch_size=2", "--steps=2", "--save_freq=2", "--device=cpu"]
    proc = cli.run("roboview.pipelines.train", *args, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out / "checkpoints" / "last" / "pretrained_model"


@pytest.fixture(scope="module")
def benchmark(tmp_path_factory) -> Path:
    """metaworld_tiny built at 64² (4 instances)."""
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build

    bench = tmp_path_factory.mktemp("metaworld_bench") / "bench"
    build(BuildConfig(output_dir=str(bench), preset="metaworld_tiny", image_size=64, num_workers=1))
    return bench


def test_demos_are_in_lerobots_metaworld_layout_and_replay_bit_for_bit(demos):
    import pandas as pd
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from roboview.demos.recorder import training_instance
    from roboview.tasks import make_env

    dataset = LeRobotDataset(REPO, root=demos)
    features = dataset.meta.features
    assert {"observation.image", "observation.state", "action"} <= set(features)
    assert not any(k.startswith("observation.images.") for k in features)
    assert dataset.meta.fps == 80 and dataset.meta.robot_type == "sawyer"
    assert tuple(features["observation.state"]["shape"]) == (4,) and tuple(features["action"]["shape"]) == (
        4,
    )
    sample = dataset[0]
    assert sample["task"] == "Push the puck to a goal"
    assert tuple(sample["observation.image"].shape) == (3, 64, 64)
    card = (demos / "README.md").read_text()
    assert "Meta-World" in card and "metaworld_task" in card and "dx, dy, dz, gripper" in card

    frames = dataset.hf_dataset.with_format("numpy")[:]
    episode = np.asarray(frames["episode_index"]) == 0
    states, actions = np.stack(frames["observation.state"])[episode], np.stack(frames["action"])[episode]
    provenance = pd.read_parquet(demos / "meta" / "roboview" / "episodes.parquet").iloc[0]
    seed = int(provenance["episode_seed"])
    instance = training_instance(np.random.default_rng(seed), "metaworld", {})
    assert instance.instance_id == provenance["instance_id"]
    env = make_env("metaworld", cameras=("top",), image_size=64)
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


def test_a_metaworld_checkpoint_fits_metaworld_and_runs_in_process(checkpoint, benchmark, tmp_path, capsys):
    config = policy_config("lerobot", path=str(checkpoint), device="cpu")
    # Its control from its action width (only Meta-World's control is 4-d), its camera LeRobot's `observation.image`.
    assert config.env_control() == "xyz_delta"
    assert config.observed_cameras() == ("top",) and config.input_image_size() == 64
    fit_policy(config, ["metaworld"])
    wrong = r"'pick_place' task's env takes control joint, ee_delta, ee_abs; .* acts in 'xyz_delta'$"
    with pytest.raises(ValueError, match=wrong):
        fit_policy(config, ["pick_place"])

    # roboview-evaluate and roboview-verify through their `main`, in this process (the command lines themselves are
    # tested in tests/core): the checkpoint's workers fork from a server that imported LeRobot once.
    from roboview.pipelines.evaluate import main as evaluate
    from roboview.pipelines.verify import main as verify

    out = tmp_path / "eval"
    evaluate(
        [
            f"--benchmark.path={benchmark}",
            "--policy.type=lerobot",
            f"--policy.path={checkpoint}",
            "--policy.device=cpu",
            "--eval.n_repeats=1",
            "--eval.max_steps=8",
            f"--output_dir={out}",
        ]
    )
    run = json.loads((out / "run.json").read_text())
    assert run["control"] == "xyz_delta"
    capsys.readouterr()
    report = verify([f"--results={out}"])
    assert report.passed and "PASS  isolation" in capsys.readouterr().out


def test_a_checkpoint_that_is_not_metaworlds_is_refused_before_any_episode(tiny_checkpoint):
    config = policy_config("lerobot", path=str(tiny_checkpoint), device="cpu")
    with pytest.raises(ValueError, match="the 'metaworld' task's env takes control xyz_delta"):
        fit_policy(config, ["metaworld"])


def _episode(policy, steps: int = 6):
    """One push-v3 baseline episode of `policy` in an evaluation worker: its row and the hand's path."""
    from roboview.benchmark.format import BenchmarkItem
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.metaworld.task import baseline_metaworld_instance

    instance = baseline_metaworld_instance()
    worker = EvalWorker(
        WorkerSpec(policy, image_size=64, max_steps=steps, record_media=True, task="metaworld")
    )
    try:
        result = worker.run(WorkItem(BenchmarkItem(instance, instance.to_record()), 0))
    finally:
        worker.close()
    return result.row, result.ee_path


def test_the_checkpoint_served_over_openpi_gives_the_in_process_episode(checkpoint):
    """RoboView's policy server holding the checkpoint behind openpi's protocol, a custom layout naming Meta-World's
    camera and its 4-d state: the served episode is the in-process one."""
    from tests.helpers.servers import free_port, start_server, stop

    local_row, local_path = _episode(policy_config("lerobot", path=str(checkpoint), device="cpu"))
    layout = "observation/image=camera:top,observation/state=state,prompt=instruction"
    port = free_port()
    server = start_server(
        checkpoint, port, "--server=openpi", "--obs_format=custom", f"--key_map={layout}", "--task=metaworld"
    )
    try:
        client = policy_config(
            "openpi",
            url=f"ws://127.0.0.1:{port}",
            obs_format="custom",
            key_map=layout,
            cameras="top",
            image_size=64,
            render_size=64,
        )
        fit_policy(client, ["metaworld"])
        assert client.env_control() == "xyz_delta"
        served_row, served_path = _episode(client)
    finally:
        stop(server)
    assert served_row["status"] == local_row["status"] == "ok"
    for key in ("instance_id", "episode_seed", "success", "steps"):
        assert served_row[key] == local_row[key], key
    np.testing.assert_allclose(served_path, local_path, rtol=0, atol=1e-6)
    assert len(local_path) == 6 and np.ptp(local_path, axis=0).max() > 1e-4  # the hand moved


def test_the_checkpoint_behind_vla_evals_lerobot_server_gives_the_in_process_episode(checkpoint):
    """vla-eval's own LeRobotModelServer holding the checkpoint, Meta-World's camera mapped onto its
    `observation.image` feature: the served episode is the in-process one."""
    from vla_eval.model_servers.lerobot import LeRobotModelServer

    from tests.helpers.servers import serving

    local_row, local_path = _episode(policy_config("lerobot", path=str(checkpoint), device="cpu"))
    model = LeRobotModelServer("act", str(checkpoint), device="cpu", image_keys={"top": "observation.image"})
    with serving(model) as url:
        # LeRobot's server leaves the control to the client (a `raw` action spec): the world's only one.
        client = policy_config("vla_eval", url=url, image_size=64, cameras="top")
        fit_policy(client, ["metaworld"])
        assert client.env_control() == "xyz_delta"
        served_row, served_path = _episode(client)
    assert served_row["status"] == local_row["status"] == "ok"
    for key in ("instance_id", "episode_seed", "success", "steps"):
        assert served_row[key] == local_row[key], key
    np.testing.assert_allclose(served_path, local_path, rtol=0, atol=1e-6)


def test_lerobot_eval_runs_the_checkpoint_on_metaworld_through_the_plugin(checkpoint, benchmark, tmp_path):
    """`lerobot-eval --env.type=roboview` on a Meta-World benchmark: its camera, image size and control read from the
    checkpoint, the one image handed as LeRobot's own Meta-World env hands it (`observation.image`)."""
    from roboview.integrations.lerobot import RoboViewEnv

    config = RoboViewEnv(task="metaworld_color", benchmark_path=str(benchmark), cameras="top", image_size=64)
    assert config.control == "xyz_delta" and config.features_map["pixels"] == "observation.image"
    assert config.features["action"].shape == (4,) and config.features["agent_pos"].shape == (4,)
    cmd = [
        str(Path(sys.executable).parent / "lerobot-eval"),
        f"--policy.path={checkpoint}",
        "--policy.device=cpu",
    ]
    cmd += ["--env.type=roboview", f"--env.benchmark_path={benchmark}", "--env.task=metaworld_color"]
    cmd += [
        "--env.max_steps=6",
        "--eval.n_episodes=2",
        "--eval.batch_size=1",
        f"--output_dir={tmp_path / 'le'}",
    ]
    proc = cli.run(
        "lerobot.scripts.lerobot_eval", *cmd[1:], cwd=tmp_path, timeout=900
    )  # lerobot-eval's module
    assert proc.returncode == 0, proc.stdout[-1500:] + proc.stderr[-1500:]
    info = json.loads((tmp_path / "le" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 2
