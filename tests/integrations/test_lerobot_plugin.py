"""RoboView as a LeRobot plugin: the installed `lerobot_env_roboview` distribution makes `--env.type=roboview`
known to lerobot-train and lerobot-eval with no --env.discover_packages_path, and lerobot-train's periodic
evaluation logs one success rate per RoboView split (roboview.pipelines.train passes the splits)."""

import ast
import importlib.metadata
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytestmark = pytest.mark.fast

ROOT = Path(__file__).resolve().parents[2]
SUITE = re.compile(r"Suite (per_group|overall) aggregated: (\{.*\})$")


def test_the_plugin_distribution_is_one_lerobot_imports():
    from lerobot.utils.import_utils import register_third_party_plugins

    names = [d.metadata["Name"] for d in importlib.metadata.distributions()]
    assert "lerobot_env_roboview" in names, (
        "not installed: `make install` installs plugins/lerobot_env_roboview"
    )
    # LeRobot's own loader imports the module named as the distribution; that module registers the env.
    register_third_party_plugins()
    from lerobot.envs.configs import EnvConfig

    from roboview.integrations.lerobot import RoboViewEnv

    assert EnvConfig.get_choice_class("roboview") is RoboViewEnv


def _suites(log: str) -> list[dict[str, dict]]:
    """Each periodic evaluation's `{"per_group": {split: metrics}, "overall": metrics}`, as lerobot-train logged it."""
    evals: list[dict[str, dict]] = []
    for line in log.splitlines():
        match = SUITE.search(line)
        if match:
            if match[1] == "per_group":
                evals.append({})
            evals[-1][match[1]] = ast.literal_eval(match[2])
    return evals


@pytest.mark.slow
def test_lerobot_train_evaluates_every_split_while_training(tiny_benchmark, tiny_demos, tmp_path):
    from roboview.benchmark.format import available_splits

    out = tmp_path / "train"
    # A real lerobot-train with no --env.discover_packages_path: the plugin distribution registers the env.
    cmd = [
        str(Path(sys.executable).parent / "lerobot-train"),
        "--dataset.repo_id=t/demos",
        f"--dataset.root={tiny_demos}",
        "--policy.type=act",
        "--policy.pretrained_backbone_weights=null",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--policy.dim_model=64",
        "--policy.dim_feedforward=128",
        "--policy.n_encoder_layers=1",
        "--policy.n_vae_encoder_layers=1",
        "--policy.chunk_size=10",
        "--policy.n_action_steps=10",
        "--batch_size=2",
        "--steps=4",
        "--save_freq=4",
        "--num_workers=0",
        "--wandb.enable=false",
        f"--output_dir={out}",
        "--env.type=roboview",
        f"--env.benchmark_path={tiny_benchmark}",
        "--env.task=all",
        "--env.limit=1",
        "--env.cameras=left_top,wrist",
        "--env.image_size=64",
        "--env.max_steps=5",
        "--env_eval_freq=2",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
    ]
    env = os.environ | {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    start, cpu = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=300, env=env
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = after.ru_utime + after.ru_stime - cpu.ru_utime - cpu.ru_stime
    assert proc.returncode == 0, proc.stdout[-3000:]
    splits = available_splits(tiny_benchmark)
    evals = _suites(proc.stdout)
    assert len(evals) == 2, proc.stdout[-3000:]  # steps 2 and 4
    for step, logged in zip((2, 4), evals):
        assert list(logged["per_group"]) == sorted(splits)
        for split, metrics in logged["per_group"].items():
            # One episode per split: its rate is 0 or 100 (%), and its video is the split's own.
            assert metrics["n_episodes"] == 1 and metrics["pc_success"] in (0.0, 100.0), (split, metrics)
            assert metrics["video_paths"] == [
                str(out / "eval" / f"videos_step_{step:06d}" / f"{split}_0" / "eval_episode_0.mp4")
            ]
            assert Path(metrics["video_paths"][0]).stat().st_size > 0
        overall = logged["overall"]
        assert overall["n_episodes"] == len(splits)
        mean = sum(m["pc_success"] for m in logged["per_group"].values()) / len(splits)
        assert overall["pc_success"] == pytest.approx(mean)
    assert (out / "checkpoints" / "000004" / "pretrained_model" / "model.safetensors").is_file()
    print(
        f"lerobot-train, 4 steps with 2 evaluations of {len(splits)} splits: {wall:.1f} s wall, {cpu_s:.1f} s CPU"
    )


@pytest.mark.slow
def test_pipelines_train_passes_the_splits_to_lerobot_train(tiny_benchmark, tiny_demos, tmp_path):
    from roboview.benchmark.format import available_splits
    from roboview.pipelines._cli import BenchmarkPath
    from roboview.pipelines.train import TrainConfig, TrainDatasetConfig, command

    def config(splits: str) -> TrainConfig:
        return TrainConfig(
            dataset=TrainDatasetConfig("t/demos", str(tiny_demos)),
            output_dir=str(tmp_path / "train"),
            benchmark=BenchmarkPath(str(tiny_benchmark)),
            eval_splits=splits,
            eval_episodes=3,
            eval_freq=50,
        )

    flags = command(config("color, dist_scale"))
    assert "--env.type=roboview" in flags and not any("discover_packages_path" in f for f in flags)
    assert {
        "--env.task=color,dist_scale",
        "--env_eval_freq=50",
        "--eval.n_episodes=3",
        "--env.limit=3",
    } <= set(flags)
    assert "--env.task=all" in command(config("all"))
    with pytest.raises(ValueError) as error:
        config("color,colour")
    assert str(error.value) == (
        f"--eval_splits='color,colour': unknown split(s) ['colour']; the benchmark at {tiny_benchmark} has: "
        f"{', '.join(available_splits(tiny_benchmark))} (comma-separated, or `all`)"
    )


@pytest.mark.slow
def test_the_plugin_runs_an_end_effector_checkpoint_in_its_control(tiny_benchmark):
    """`--env.control=ee_delta`: 7-d LIBERO-convention actions in, the end-effector state as agent_pos out."""
    from lerobot.utils.constants import ACTION

    from roboview.integrations.lerobot import RoboViewEnv
    from roboview.integrations.lerobot.env import RoboViewEvalEnv
    from roboview.tasks.env import EE_STATE_KEY, STATE_KEY

    config = RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark), image_size=64, control="ee_delta")
    assert config.features[ACTION].shape == (7,) and config.split_kwargs("color")["control"] == "ee_delta"
    with pytest.raises(
        ValueError, match=r"--env.control='ee' unknown; allowed: joint, ee_delta, ee_abs, xyz_delta"
    ):
        RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark), control="ee")
    env = RoboViewEvalEnv(**config.split_kwargs("color"))
    try:
        obs, _ = env.reset(seed=1000)
        assert env.action_space.shape == (7,) and np.array_equal(obs["agent_pos"], env.env.ee_state())
        up = np.array([0, 0, 1, 0, 0, 0, -1], np.float32)  # +5 cm, gripper open
        after, *_ = env.step(up)
        assert after["agent_pos"][2] > obs["agent_pos"][2] + 0.02  # the pinch point rose
        assert not np.allclose(after["agent_pos"], env.env.state())  # the EE state, not the joint state
        assert (
            EE_STATE_KEY in env.env.observation_space.spaces and STATE_KEY in env.env.observation_space.spaces
        )
    finally:
        env.close()


@pytest.mark.slow
def test_the_plugin_fits_the_checkpoint_lerobot_eval_loads(tiny_benchmark, tmp_path, monkeypatch):
    """The checkpoint's own image side is adopted (and a different --env.image_size refused); an end-effector
    checkpoint under the default joint control is refused naming --env.control. The checkpoint is the one
    lerobot-eval's own parser reads from --policy.path; its config.json is written by LeRobot's ACTConfig."""
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.utils.constants import ACTION

    from roboview.integrations.lerobot import RoboViewEnv

    def checkpoint(name: str, side: int, width: int) -> Path:
        folder = tmp_path / name
        folder.mkdir()
        ACTConfig(
            input_features={
                "observation.images.left_top": PolicyFeature(FeatureType.VISUAL, (3, side, side)),
                "observation.state": PolicyFeature(FeatureType.STATE, (8,)),
            },
            output_features={ACTION: PolicyFeature(FeatureType.ACTION, (width,))},
        )._save_pretrained(folder)
        return folder

    joint64, ee64 = checkpoint("joint64", 64, 8), checkpoint("ee64", 64, 7)
    monkeypatch.setattr("sys.argv", ["lerobot-eval", f"--policy.path={joint64}", "--env.type=roboview"])
    config = RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark))
    assert config.image_size == 64 and config.features["pixels/left_top"].shape == (64, 64, 3)
    with pytest.raises(ValueError) as error:
        RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark), image_size=96)
    assert str(error.value) == (
        f"--env.image_size=96 but the checkpoint {joint64} was trained on 64×64 images; drop the flag (its size is "
        "used) or pass 64"
    )
    monkeypatch.setattr("sys.argv", ["lerobot-eval", f"--policy.path={ee64}"])
    with pytest.raises(
        ValueError, match=r"takes 8-d actions but the checkpoint .* answers 7: pass --env.control=ee_delta"
    ):
        RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark))
    assert RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark), control="ee_delta").image_size == 64
    monkeypatch.setattr("sys.argv", ["lerobot-train", "--policy.type=act"])  # no checkpoint to read: 96
    assert RoboViewEnv(task="color", benchmark_path=str(tiny_benchmark)).image_size == 96


def test_eval_info_carries_each_values_paired_difference_to_the_control_arm(tmp_path):
    """convert's `add_control_arm`: each single-factor group of eval_info.json gains its control arm and, per value,
    `delta_control` with `delta_control_ci95` beside `p_control`, the numbers metrics.json holds."""
    import json

    from roboview.eval.statistics.metrics import MetricsConfig, compute_metrics
    from roboview.integrations.lerobot.convert import add_control_arm
    from roboview.variation.factors import baselines

    red, near = baselines()["color"], baselines()["dist_scale"]
    rows = [
        {
            "policy": "lerobot-eval",
            "split": "color",
            "factor": "color",
            "value": value,
            "context_id": f"c{r // 6}",
            "instance_id": f"color/{value}/c{r // 6}",
            "repeat": r % 6,
            "success": success,
            "color": value,
            "dist_scale": near,
        }
        for value, outcomes in ((red, [1] * 12), ("blue", [1, 1] + [0] * 10))
        for r, success in enumerate(outcomes)
    ]
    info = {"per_group": {"color": {"pc_success": 58.3, "n_episodes": 24}}, "per_task": []}
    path = tmp_path / "eval_info.json"
    add_control_arm(path, info, rows)
    group = json.loads(path.read_text())["per_group"]["color"]
    assert group["pc_success"] == 58.3 and (group["sr_control"], group["n_control_episodes"]) == (1.0, 12)
    assert group["sr_control_ci95"] == pytest.approx([0.025 ** (1 / 12), 1.0])  # 12/12, Clopper–Pearson
    blue = group["per_value"]["blue"]
    assert (blue["delta_control"], blue["n_control_pairs"]) == (pytest.approx(-10 / 12), 12)
    assert blue["p_control"] == pytest.approx(2 * 0.5**10)  # McNemar exact: 10 pairs differ, all one way
    assert blue["delta_control_ci95"] == pytest.approx([-0.9530, -0.4619], abs=1e-4)  # Newcombe, φ = 0
    native = compute_metrics(pd.DataFrame(rows), MetricsConfig(n_perm=20, n_glm=5, max_perm=20, n_boot=0))
    assert group["per_value"] == {
        v: {k: native["splits"]["color"]["per_value"][v][k] for k in group["per_value"][v]}
        for v in group["per_value"]
    }
