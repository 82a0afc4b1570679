"""Meta-World episode throughput: `roboview-evaluate` against LeRobot's own `lerobot-eval --env.type=metaworld`, whole
commands, same checkpoint, same task, same number of episodes and step budget.

    python -m benchmarks.metaworld_vs_lerobot_eval --checkpoint=CKPT/pretrained_model \\
        --benchmark.path=outputs/metaworld/benchmark [--episodes=4] [--num_workers=1] [--batch_size=1] \\
        [--output_dir=outputs/bench/metaworld_vs_lerobot_eval]

The episodes: push-v3 at baseline, `--episodes` of them. lerobot-eval runs seeds 1000 … 1000+episodes−1; RoboView runs
the baseline row of the benchmark's `metaworld_color` split (`--preset=metaworld_tiny`) with `--eval.n_repeats=
episodes`, whose seeds are its own (episode_seed(context, repeat)): the same task and distribution of object and goal
positions, not the same draws. lerobot-eval renders corner2 at 480² every step (LeRobot's MetaworldEnv always does)
and runs its `--eval.batch_size` envs in one process; RoboView renders the camera at the checkpoint's image size,
only when the policy reads it (an ACT chunk: once per `n_action_steps`), in `--num_workers` processes. Train the
checkpoint on 480² demos for a like-for-like image size. Timed: each command from start to exit (imports, env
creation, every episode, the files they write). Writes `metaworld_vs_lerobot_eval.json` (episodes/hour of each, the
ratio, steps and success on both) and prints one line.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.libero_vs_lerobot_eval import timed
from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads
from roboview.eval.running.results import PARQUET


@dataclass
class BenchmarkPath:
    # A benchmark built with --preset=metaworld_tiny (its metaworld_color split holds push-v3 at baseline).
    path: str = "outputs/metaworld/benchmark"


@dataclass
class MetaWorldVsLeRobotConfig:
    # A LeRobot checkpoint trained on Meta-World (observation.image, 4-d state and action).
    checkpoint: str = ""
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Episodes of push-v3 on each side.
    episodes: int = 4
    # RoboView's worker processes.
    num_workers: int = 1
    # lerobot-eval's envs stepped together in its process (--eval.batch_size).
    batch_size: int = 1
    # Folder of both runs' outputs, their logs and metaworld_vs_lerobot_eval.json.
    output_dir: str = "outputs/bench/metaworld_vs_lerobot_eval"

    def __post_init__(self) -> None:
        if not self.checkpoint or not (Path(self.checkpoint) / "config.json").is_file():
            raise ValueError(
                f"--checkpoint={self.checkpoint!r} must be a folder holding a LeRobot config.json"
            )
        if min(self.episodes, self.num_workers, self.batch_size) < 1:
            raise ValueError("--episodes, --num_workers and --batch_size must be ≥ 1")


def run(cfg: MetaWorldVsLeRobotConfig) -> dict:
    import pandas as pd

    from roboview.policies.lerobot_policy import checkpoint_image_size

    out = Path(cfg.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    side = checkpoint_image_size(cfg.checkpoint)
    env = dict(os.environ, HF_HUB_OFFLINE="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    bin_dir = Path(sys.executable).parent
    lerobot_dir, roboview_dir = out / "lerobot_eval", out / "roboview"
    for folder in (lerobot_dir, roboview_dir):
        if folder.exists():
            shutil.rmtree(folder)
    lerobot_cmd = [str(bin_dir / "lerobot-eval"), f"--policy.path={cfg.checkpoint}", "--policy.device=cpu"]
    lerobot_cmd += ["--env.type=metaworld", "--env.task=push-v3", f"--eval.n_episodes={cfg.episodes}"]
    lerobot_cmd += [f"--eval.batch_size={cfg.batch_size}", "--seed=1000", f"--output_dir={lerobot_dir}"]
    lerobot_s = timed(lerobot_cmd, env, out / "lerobot_eval.log")
    roboview_cmd = [str(bin_dir / "roboview-evaluate"), f"--benchmark.path={cfg.benchmark.path}"]
    roboview_cmd += [
        "--benchmark.splits=metaworld_color",
        "--benchmark.values=original",
        "--policy.type=lerobot",
    ]
    roboview_cmd += [
        f"--policy.path={cfg.checkpoint}",
        "--policy.device=cpu",
        f"--eval.n_repeats={cfg.episodes}",
    ]
    roboview_cmd += [f"--eval.num_workers={cfg.num_workers}", f"--output_dir={roboview_dir}"]
    roboview_s = timed(roboview_cmd, env, out / "roboview.log")
    info = json.loads((lerobot_dir / "eval_info.json").read_text())
    lerobot_success = [bool(x) for task in info["per_task"] for x in task["metrics"]["successes"]]
    rows = pd.read_parquet(roboview_dir / PARQUET).sort_values("repeat")
    result = {
        "checkpoint": cfg.checkpoint,
        "episodes": cfg.episodes,
        "image_size": {"lerobot_eval": 480, "roboview": side},
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
            "success": [bool(s) for s in rows["success"]],
            "steps": [int(s) for s in rows["steps"]],
        },
        "speedup": round(lerobot_s / roboview_s * len(rows) / cfg.episodes, 2),
    }
    (out / "metaworld_vs_lerobot_eval.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def summary(cfg: MetaWorldVsLeRobotConfig, result: dict) -> None:
    le, rv = result["lerobot_eval"], result["roboview"]
    print(
        f"[metaworld_vs_lerobot_eval] {result['episodes']} push-v3 episodes: lerobot-eval "
        f"{le['episodes_per_hour']:.0f} episodes/h ({le['wall_s']:.0f} s, 480², success {sum(le['success'])}), "
        f"roboview-evaluate {rv['episodes_per_hour']:.0f} episodes/h ({rv['wall_s']:.0f} s, "
        f"{result['image_size']['roboview']}², success {sum(rv['success'])}): {result['speedup']:.2f}×"
    )


def main(args: list[str] | None = None) -> dict:
    return cli_main(MetaWorldVsLeRobotConfig, run, summary, args=args)


if __name__ == "__main__":
    main()
