"""A Meta-World checkpoint on RoboView's Meta-World scenes.

Demos collected by `roboview-collect` in the layout of LeRobot's Meta-World datasets (`observation.image`, 4-d
`observation.state` and `action`, 80 fps) load with `LeRobotDataset` and replay bit for bit; an ACT trained on them
by `roboview-train` is evaluated in-process by `roboview-evaluate` (its control, camera and image size read from the
checkpoint) and the results verify; a checkpoint that is not Meta-World's is refused before any episode.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("metaworld", reason="Meta-World not installed (make install-metaworld)")

from roboview.policies.fit import fit_policy  # noqa: E402
from roboview.policies.types import policy_config  # noqa: E402

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
    cmd = [
        sys.executable,
        "-m",
        "roboview.pipelines.train",
        f"--dataset.repo_id={REPO}",
        f"--dataset.root={demos}",
    ]
    cmd += [f"--output_dir={out}", "--batch_size=2", "--steps=2", "--save_freq=2", "--device=cpu"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out / "checkpoints" / "last" / "pretrained_model"


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


def test_a_metaworld_checkpoint_fits_metaworld_and_runs_in_process(checkpoint, tmp_path):
    config = policy_config("lerobot", path=str(checkpoint), device="cpu")
    # Its control from its action width (only Meta-World's control is 4-d), its camera LeRobot's `observation.image`.
    assert config.env_control() == "xyz_delta"
    assert config.observed_cameras() == ("top",) and config.input_image_size() == 64
    fit_policy(config, ["metaworld"])
    wrong = r"'pick_place' task's env takes control joint, ee_delta, ee_abs; .* acts in 'xyz_delta'$"
    with pytest.raises(ValueError, match=wrong):
        fit_policy(config, ["pick_place"])

    bench, out = tmp_path / "bench", tmp_path / "eval"
    build = [sys.executable, "-m", "roboview.pipelines.build_benchmark", "--preset=metaworld_tiny"]
    proc = subprocess.run(
        [*build, "--image_size=64", f"--output_dir={bench}", "--num_workers=1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    evaluate = [
        sys.executable,
        "-m",
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        "--policy.type=lerobot",
    ]
    evaluate += [
        f"--policy.path={checkpoint}",
        "--policy.device=cpu",
        "--eval.n_repeats=1",
        "--eval.max_steps=8",
    ]
    proc = subprocess.run([*evaluate, f"--output_dir={out}"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    run = json.loads((out / "run.json").read_text())
    assert run["control"] == "xyz_delta"
    proc = subprocess.run(
        [sys.executable, "-m", "roboview.pipelines.verify", f"--results={out}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0 and "PASS  isolation" in proc.stdout, (
        proc.stdout[-2000:] + proc.stderr[-1000:]
    )


def test_a_checkpoint_that_is_not_metaworlds_is_refused_before_any_episode(tiny_checkpoint):
    config = policy_config("lerobot", path=str(tiny_checkpoint), device="cpu")
    with pytest.raises(ValueError, match="the 'metaworld' task's env takes control xyz_delta"):
        fit_policy(config, ["metaworld"])
