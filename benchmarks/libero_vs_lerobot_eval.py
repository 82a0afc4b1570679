"""LIBERO episode throughput: `roboview-evaluate` against LeRobot's own `lerobot-eval --env.type=libero`, whole
commands, same checkpoint, same episodes.

    python -m benchmarks.libero_vs_lerobot_eval --checkpoint=CKPT/pretrained_model \\
        --benchmark.path=outputs/libero/benchmark [--episodes=10] [--num_workers=2] [--batch_size=1] \\
        [--output_dir=outputs/bench/libero_vs_lerobot_eval]

The episodes: `libero_object` task 0 from init states 0 … episodes−1, every factor at its baseline — lerobot-eval's
episodes of `--env.task=libero_object --env.task_ids=[0]` (one init state per episode, in order) and the baseline
rows of the benchmark's `libero_color` split (its contexts are those init states: build it with
`--preset=libero_small`). Both render at the checkpoint's image size. lerobot-eval renders both cameras every step
and runs its `--eval.batch_size` envs in one process; RoboView renders a camera only when the policy reads it and
runs `--num_workers` processes. Timed: each command from start to exit (imports, env creation, every episode, the
files they write). Writes `libero_vs_lerobot_eval.json` (episodes/hour of each, the ratio, each episode's success on
both) and prints one line. LeRobot's LIBERO needs `python -m roboview.libero` run once (`make install-libero` does).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads
from roboview.eval.running.results import PARQUET


@dataclass
class BenchmarkPath:
    # A benchmark built with --preset=libero_small (its libero_color split holds libero_object/0's init states).
    path: str = "outputs/libero/benchmark"


@dataclass
class LiberoVsLeRobotConfig:
    # A LeRobot checkpoint trained on LIBERO (image / image2 features, 7-d action).
    checkpoint: str = ""
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Episodes: init states 0 … episodes−1 of libero_object task 0.
    episodes: int = 10
    # RoboView's worker processes.
    num_workers: int = 2
    # lerobot-eval's envs stepped together in its process (--eval.batch_size).
    batch_size: int = 1
    # Folder of both runs' outputs, their logs and libero_vs_lerobot_eval.json.
    output_dir: str = "outputs/bench/libero_vs_lerobot_eval"

    def __post_init__(self) -> None:
        if not self.checkpoint or not (Path(self.checkpoint) / "config.json").is_file():
            raise ValueError(
                f"--checkpoint={self.checkpoint!r} must be a folder holding a LeRobot config.json"
            )
        if min(self.episodes, self.num_workers, self.batch_size) < 1:
            raise ValueError("--episodes, --num_workers and --batch_size must be ≥ 1")


def timed(cmd: list[str], env: dict, log: Path) -> float:
    start = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
    if proc.returncode:
        raise RuntimeError(f"{cmd[0]} exited {proc.returncode}; see {log}")
    return time.perf_counter() - start


def run(cfg: LiberoVsLeRobotConfig) -> dict:
    import pandas as pd

    from roboview.libero.bootstrap import ensure_libero, link_assets
    from roboview.policies.lerobot_policy import checkpoint_image_size

    ensure_libero()
    link_assets()
    out = Path(cfg.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    side = checkpoint_image_size(cfg.checkpoint)
    env = dict(os.environ, HF_HUB_OFFLINE="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    bin_dir = Path(sys.executable).parent
    lerobot_dir, roboview_dir = out / "lerobot_eval", out / "roboview"
    for folder in (lerobot_dir, roboview_dir):
        if folder.exists():
            shutil.rmtree(folder)
    lerobot_s = timed(
        [
            str(bin_dir / "lerobot-eval"),
            f"--policy.path={cfg.checkpoint}",
            "--policy.device=cpu",
            "--env.type=libero",
            "--env.task=libero_object",
            "--env.task_ids=[0]",
            f"--env.observation_height={side}",
            f"--env.observation_width={side}",
            f"--eval.n_episodes={cfg.episodes}",
            f"--eval.batch_size={cfg.batch_size}",
            f"--output_dir={lerobot_dir}",
        ],
        env,
        out / "lerobot_eval.log",
    )
    roboview_s = timed(
        [
            str(bin_dir / "roboview-evaluate"),
            f"--benchmark.path={cfg.benchmark.path}",
            "--benchmark.splits=libero_color",
            "--benchmark.values=original",
            f"--eval.limit={cfg.episodes}",
            "--policy.type=lerobot",
            f"--policy.path={cfg.checkpoint}",
            "--policy.device=cpu",
            "--eval.n_repeats=1",
            f"--eval.num_workers={cfg.num_workers}",
            f"--output_dir={roboview_dir}",
        ],
        env,
        out / "roboview.log",
    )
    info = json.loads((lerobot_dir / "eval_info.json").read_text())
    lerobot_success = [bool(x) for task in info["per_task"] for x in task["metrics"]["successes"]]
    rows = pd.read_parquet(roboview_dir / PARQUET)
    rows["init"] = rows["init_state"].astype(int)
    roboview_success = [bool(s) for s in rows.sort_values("init")["success"]]
    result = {
        "checkpoint": cfg.checkpoint,
        "episodes": cfg.episodes,
        "image_size": side,
        "lerobot_eval": {
            "wall_s": round(lerobot_s, 1),
            "episodes_per_hour": round(3600 * cfg.episodes / lerobot_s, 1),
            "batch_size": cfg.batch_size,
            "success": lerobot_success,
        },
        "roboview": {
            "wall_s": round(roboview_s, 1),
            "episodes_per_hour": round(3600 * len(rows) / roboview_s, 1),
            "num_workers": cfg.num_workers,
            "success": roboview_success,
        },
        "speedup": round(lerobot_s / roboview_s * len(rows) / cfg.episodes, 2),
    }
    (out / "libero_vs_lerobot_eval.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def summary(cfg: LiberoVsLeRobotConfig, result: dict) -> None:
    le, rv = result["lerobot_eval"], result["roboview"]
    print(
        f"[libero_vs_lerobot_eval] {result['episodes']} episodes at {result['image_size']}²: lerobot-eval "
        f"{le['episodes_per_hour']:.0f} episodes/h ({le['wall_s']:.0f} s, success {sum(le['success'])}), "
        f"roboview-evaluate {rv['episodes_per_hour']:.0f} episodes/h ({rv['wall_s']:.0f} s, success "
        f"{sum(rv['success'])}): {result['speedup']:.2f}×"
    )


def main(args: list[str] | None = None) -> dict:
    return cli_main(LiberoVsLeRobotConfig, run, summary, args=args)


if __name__ == "__main__":
    main()
