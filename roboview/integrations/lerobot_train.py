"""lerobot-train's command line for RoboView's reference policy: ACT-small (dim_model 256, feed-forward 1024, 2
encoder layers, the backbone's learning rate that of the transformer) with no pretrained backbone (the default
downloads ImageNet weights, which fails offline), a resume from a run folder's last checkpoint, and lerobot-train's
periodic evaluation on frozen RoboView splits (the `roboview` env of the lerobot_env_roboview plugin).

Kept apart from the `roboview.integrations.lerobot` package, which imports lerobot: this module writes the command
line, and imports lerobot only to run it (`run_trainer`, in this process: a second interpreter would import torch and
LeRobot's policies again, ≈ 7 CPU-seconds here).
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

TRAINER = (sys.executable, "-m", "lerobot.scripts.lerobot_train")


@dataclass(frozen=True)
class ActRecipe:
    """The reference recipe's settings: optimizer steps, checkpoint interval, batch size, learning rate, action
    chunk and the actions of each chunk run, the torch device and the data-loading workers."""

    steps: int = 6000
    save_freq: int = 1000
    batch_size: int = 16
    lr: float = 1e-4
    chunk_size: int = 20
    n_action_steps: int = 10
    device: str = "cpu"
    num_workers: int = 0


@dataclass(frozen=True)
class PeriodicEval:
    """lerobot-train's evaluation while training: the benchmark folder, its splits (comma-separated, or `all`),
    the episodes per split and the steps between evaluations."""

    benchmark_path: str
    splits: str
    episodes: int
    freq: int


def last_checkpoint(output_dir: Path) -> Path | None:
    """The train_config.json of a run folder's last checkpoint; None when it holds none."""
    config = output_dir / "checkpoints" / "last" / "pretrained_model" / "train_config.json"
    return config if config.is_file() else None


def dataset_cameras(root: str | Path) -> dict[str, list[int]]:
    """camera → (H, W, 3) of every image feature of the LeRobot dataset at `root`."""
    from roboview.tasks.world import camera_of_feature

    features = json.loads((Path(root) / "meta" / "info.json").read_text())["features"]
    return {camera_of_feature(k): v["shape"] for k, v in features.items() if camera_of_feature(k)}


def eval_flags(dataset_root: str, periodic: PeriodicEval) -> list[str]:
    """lerobot-train's flags for periodic evals on the RoboView splits (the dataset's cameras and image size)."""
    images = dataset_cameras(dataset_root)
    side = next(iter(images.values()))[0]  # (H, W, 3): square, one size for every camera
    return [
        "--env.type=roboview",
        f"--env.benchmark_path={periodic.benchmark_path}",
        f"--env.task={periodic.splits.replace(' ', '')}",
        f"--env.limit={periodic.episodes}",
        f"--env.cameras={','.join(images)}",
        f"--env.image_size={side}",
        f"--env_eval_freq={periodic.freq}",
        f"--eval.n_episodes={periodic.episodes}",
        f"--eval.batch_size={min(periodic.episodes, 8)}",
    ]


def check_new_run(output_dir: Path) -> None:
    """ValueError unless `output_dir`, holding no checkpoint, is new or empty: a fresh run writes there."""
    if output_dir.exists() and any(output_dir.iterdir()):
        raise ValueError(
            f"--output_dir={output_dir} is not empty and holds no checkpoint to resume; choose a new folder"
        )


def resume_command(checkpoint: Path, steps: int) -> list[str]:
    """lerobot-train resuming from `checkpoint` (last_checkpoint's) towards `steps` in total."""
    return [*TRAINER, f"--config_path={checkpoint}", "--resume=true", f"--steps={steps}"]


def fresh_command(
    repo_id: str, root: str, output_dir: Path, recipe: ActRecipe, periodic: PeriodicEval | None = None
) -> list[str]:
    """lerobot-train on the dataset (`repo_id` at `root`) with the recipe, into `output_dir` (check_new_run's)."""
    return [
        *TRAINER,
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={root}",
        "--policy.type=act",
        "--policy.pretrained_backbone_weights=null",
        "--policy.push_to_hub=false",
        f"--policy.device={recipe.device}",
        "--policy.dim_model=256",
        "--policy.dim_feedforward=1024",
        "--policy.n_encoder_layers=2",
        "--policy.n_vae_encoder_layers=2",
        f"--policy.chunk_size={recipe.chunk_size}",
        f"--policy.n_action_steps={recipe.n_action_steps}",
        f"--policy.optimizer_lr={recipe.lr}",
        f"--policy.optimizer_lr_backbone={recipe.lr}",
        f"--batch_size={recipe.batch_size}",
        f"--steps={recipe.steps}",
        f"--save_freq={recipe.save_freq}",
        f"--log_freq={min(100, recipe.save_freq)}",
        f"--num_workers={recipe.num_workers}",
        "--wandb.enable=false",
        f"--output_dir={output_dir}",
        f"--job_name={output_dir.name}",
        *(eval_flags(root, periodic) if periodic is not None else []),
    ]


def thread_env(threads: int) -> dict[str, str]:
    """The trainer's torch threads, as environment variables."""
    return {"OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}


def run_trainer(cmd: list[str], threads: int) -> None:
    """Run lerobot-train's `cmd` (as `fresh_command` or `resume_command` write it) in this process, as its console
    script runs it, with `threads` CPU threads (torch's now, and in the environment its data-loading and evaluation
    processes inherit). RuntimeError when it exits with an error status; an exception in the trainer propagates with
    its traceback."""
    import torch
    from lerobot.scripts import lerobot_train

    if tuple(cmd[: len(TRAINER)]) != TRAINER:
        raise ValueError(f"not a lerobot-train command: {cmd[: len(TRAINER)]}")
    saved = {name: os.environ.get(name) for name in thread_env(threads)}
    argv, torch_threads = sys.argv, torch.get_num_threads()
    os.environ.update(thread_env(threads))
    torch.set_num_threads(threads)
    sys.argv = ["lerobot-train", *cmd[len(TRAINER) :]]
    try:
        lerobot_train.main()
    except SystemExit as exc:
        if exc.code not in (None, 0):
            raise RuntimeError(f"lerobot-train exited with {exc.code}; its log is above") from None
    finally:
        sys.argv = argv
        torch.set_num_threads(torch_threads)
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
