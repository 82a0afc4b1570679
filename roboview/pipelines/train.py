"""Train a reference policy on `roboview.pipelines.collect` demos: lerobot's own trainer, the recipe that works here.

    roboview-train --dataset.repo_id=roboview/pick_place_96 --dataset.root=outputs/demos96 \
        --output_dir=outputs/train_act96 [--steps=6000] [--device=auto] \
        [--benchmark.path=outputs/benchmark --eval_splits=color,camera_pose --eval_freq=1000]

A thin layer over `lerobot-train`: it checks the dataset, then runs lerobot's trainer with
ACT-small (dim_model 256, feed-forward 1024, 2 encoder layers, chunk 20 executing 10, lr 1e-4 for
the backbone too, batch 16) and *no* pretrained backbone (the default downloads ImageNet weights,
which fails offline). Images are used at the size they were collected (`--dataset.image_size` of
collect): ACT has no resize step, and evaluation renders the checkpoint's own size. Checkpoints
land in OUTPUT/checkpoints/<step>/pretrained_model every `--save_freq` steps; rerunning the same
command resumes from the last one (lerobot's `--resume`). Measured step time: docs/results/act_ref.md.
With `--benchmark.path`, lerobot-train evaluates the policy every `--eval_freq` steps on the RoboView splits
`--eval_splits` names (the `roboview` env of the lerobot_env_roboview plugin) and logs each split's success.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from roboview.core.cli_errors import flag_errors
from roboview.integrations.lerobot_train import (
    ActRecipe,
    PeriodicEval,
    check_new_run,
    fresh_command,
    last_checkpoint,
    resume_command,
    run_trainer,
    thread_env,
)
from roboview.pipelines._cli import BenchmarkPath, cli_main
from roboview.policies.devices import DEVICES, resolve_device


@dataclass
class TrainDatasetConfig:
    # repo_id the dataset was collected under (--dataset.repo_id of roboview.pipelines.collect).
    repo_id: str = "roboview/pick_place"
    # Local dataset folder written by roboview.pipelines.collect.
    root: str = ""


@dataclass
class TrainConfig:
    dataset: TrainDatasetConfig = field(default_factory=TrainDatasetConfig)
    # Run folder: checkpoints, logs; rerun the same command to resume from its last checkpoint.
    output_dir: str = "outputs/train_act"
    # Optimizer steps in total (a resumed run continues towards the same total).
    steps: int = 6000
    # Save a checkpoint every this many steps.
    save_freq: int = 1000
    # Batch size.
    batch_size: int = 16
    # Learning rate of the transformer and of the ResNet-18 backbone.
    lr: float = 1e-4
    # auto (CUDA when present), cpu or cuda.
    device: str = "auto"
    # ACT action chunk length: actions predicted per inference.
    chunk_size: int = 20
    # Actions of each chunk run before the next inference (at most chunk_size).
    n_action_steps: int = 10
    # Periodic evaluation while training, through lerobot-train's own eval loop on frozen RoboView splits
    # (`--env.type=roboview`, the lerobot_env_roboview plugin); no --benchmark.path: no periodic evaluation.
    # lerobot-train logs each split's success rate (`Suite per_group aggregated`) and the overall one; the
    # episode videos land in OUT/eval/.
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Periodic evaluation: the benchmark splits it runs (comma-separated, or `all`), one success rate each.
    eval_splits: str = "color"
    # Periodic evaluation: episodes per split per evaluation (the split's first instances, once each).
    eval_episodes: int = 10
    # Periodic evaluation: run one every this many optimizer steps.
    eval_freq: int = 1000
    # CPU threads of the trainer's torch (OMP_NUM_THREADS); 0: one fewer than this machine's cores, at least 1.
    # torch's own default (every core) spins threads that fight anything else on the CPU: measured on 2 cores
    # with other work running, 9.3 s per step with the default and 1.1 s with one thread, same losses.
    num_threads: int = 0
    # lerobot-train's data-loading workers (video decoding). 0: in the trainer's process, right on a CPU, where
    # workers would take cores from the trainer; on a GPU the decoding is the bottleneck: give it most cores
    # (12 on a 16-core H200 machine fed 25-32 steps/s, docs/results/act_ref.md).
    num_workers: int = 0
    # Print lerobot-train's command line instead of running it.
    dry_run: bool = False

    def __post_init__(self) -> None:
        if self.device not in DEVICES:
            raise ValueError(f"unknown --device={self.device!r}; allowed: {', '.join(DEVICES)}")
        for name in (
            "steps",
            "save_freq",
            "batch_size",
            "chunk_size",
            "n_action_steps",
            "eval_episodes",
            "eval_freq",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"--{name}={getattr(self, name)} must be a positive count")
        if self.num_threads < 0:
            raise ValueError(f"--num_threads={self.num_threads} must be ≥ 0 (0 = one fewer than the cores)")
        if self.num_workers < 0:
            raise ValueError(
                f"--num_workers={self.num_workers} must be ≥ 0 (0 = load data in the trainer's process)"
            )
        if self.n_action_steps > self.chunk_size:
            raise ValueError(
                f"--n_action_steps={self.n_action_steps} cannot exceed --chunk_size={self.chunk_size}"
            )
        info = Path(self.dataset.root) / "meta" / "info.json"
        if not self.dataset.root or not info.is_file():
            raise ValueError(
                f"--dataset.root={self.dataset.root!r} holds no LeRobot dataset (meta/info.json "
                "missing); collect one with `roboview-collect`"
            )
        from roboview.tasks.world import camera_of_feature

        cameras = [k for k in json.loads(info.read_text())["features"] if camera_of_feature(k)]
        if not cameras:
            raise ValueError(
                f"--dataset.root={self.dataset.root} has no camera features; ACT needs at least one"
            )
        if self.benchmark.path:
            from roboview.benchmark.format import available_splits, load_benchmark

            # An unknown folder or split fails now, not at the first periodic evaluation.
            with flag_errors("--benchmark.path"):
                available = available_splits(self.benchmark.path)
            splits = [s.strip() for s in self.eval_splits.split(",") if s.strip()]
            unknown = [s for s in splits if s not in available] if splits != ["all"] else []
            if unknown or not splits:
                raise ValueError(
                    f"--eval_splits={self.eval_splits!r}: unknown split(s) {unknown}; the benchmark at "
                    f"{self.benchmark.path} has: {', '.join(available)} (comma-separated, or `all`)"
                )
            with flag_errors("--benchmark.path"):
                load_benchmark(self.benchmark.path, None if splits == ["all"] else splits)  # checksums

    @property
    def periodic_eval(self) -> PeriodicEval | None:
        """The evaluations while training on the RoboView splits; None without --benchmark.path."""
        if not self.benchmark.path:
            return None
        return PeriodicEval(self.benchmark.path, self.eval_splits, self.eval_episodes, self.eval_freq)

    @property
    def threads(self) -> int:
        """The trainer's torch threads: --num_threads, else one fewer than the cores (at least 1)."""
        return self.num_threads or max(1, (os.cpu_count() or 1) - 1)


def command(cfg: TrainConfig) -> list[str]:
    """lerobot-train's argument list: a fresh run, or a resume from the run folder's last checkpoint."""
    out = Path(cfg.output_dir)
    resume = last_checkpoint(out)
    if resume is not None:
        return resume_command(resume, cfg.steps)
    check_new_run(out)
    with flag_errors("--device"):
        device = resolve_device(cfg.device)
    recipe = ActRecipe(
        cfg.steps,
        cfg.save_freq,
        cfg.batch_size,
        cfg.lr,
        cfg.chunk_size,
        cfg.n_action_steps,
        device,
        cfg.num_workers,
    )
    return fresh_command(cfg.dataset.repo_id, cfg.dataset.root, out, recipe, cfg.periodic_eval)


def run(cfg: TrainConfig) -> Path:
    """Train (or resume); returns the last checkpoint's pretrained_model folder."""
    cmd = command(cfg)
    if cfg.dry_run:
        print(" ".join([*(f"{k}={v}" for k, v in thread_env(cfg.threads).items()), *cmd]))
    else:
        print(f"[train] lerobot-train with {cfg.threads} CPU thread(s) (--num_threads)", flush=True)
        run_trainer(cmd, cfg.threads)
    return Path(cfg.output_dir) / "checkpoints" / "last" / "pretrained_model"


def _summary(cfg: TrainConfig, checkpoint: Path) -> None:
    if not cfg.dry_run:
        print(
            f"[train] checkpoint: {checkpoint} (evaluate: roboview-evaluate --policy.type=lerobot "
            f"--policy.path={checkpoint} ...)"
        )


def main(args: list[str] | None = None) -> Path:
    return cli_main(TrainConfig, run, _summary, (ValueError, RuntimeError), args)


if __name__ == "__main__":
    main()
