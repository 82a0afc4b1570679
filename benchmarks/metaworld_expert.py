"""Meta-World scripted-expert success: Meta-World's own scripted policies over the registered tasks × seeds, at
baseline, through RoboView's `metaworld` env (LeRobot's episodes: the seed draws the object's and goal's positions).

    python -m benchmarks.metaworld_expert [--tasks=push-v3,pick-place-v3] [--seeds=10] [--first_seed=1000]
        [--output=outputs/bench/metaworld_expert.json]

Why: the expert is the policy-free reference of a Meta-World visual-bias study (a benchmark that biases it is broken);
this measures how often it solves the unmodified scenes within Meta-World's 500 steps, no camera rendered. Writes a
JSON (every episode, per-task success, mean steps, seconds) and prints a table.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads


@dataclass
class MetaWorldExpertConfig:
    # Tasks to run (empty: every registered Meta-World task).
    tasks: list[str] = field(default_factory=list)
    # Episodes per task: seeds first_seed … first_seed + seeds − 1.
    seeds: int = 10
    # The first episode's seed (lerobot-eval's episodes start at 1000).
    first_seed: int = 1000
    # JSON file the results are written to.
    output: str = "outputs/bench/metaworld_expert.json"

    def __post_init__(self) -> None:
        if self.seeds < 1:
            raise ValueError(f"--seeds={self.seeds} must be ≥ 1")


def run(cfg: MetaWorldExpertConfig) -> dict:
    from roboview.metaworld.task import OBJECTS, baseline_metaworld_instance
    from roboview.tasks import load_task, make_env

    bad = [t for t in cfg.tasks if t not in OBJECTS]
    if bad:
        raise ValueError(f"--tasks={','.join(bad)} not registered; allowed: {', '.join(OBJECTS)}")
    env = make_env("metaworld", image_size=64)
    expert = load_task("metaworld").make_expert(env)
    rows = []
    try:
        for task in cfg.tasks or OBJECTS:
            for seed in range(cfg.first_seed, cfg.first_seed + cfg.seeds):
                start = time.perf_counter()
                env.reset(seed=seed, options={"instance": baseline_metaworld_instance(task)})
                expert.reset()
                terminated = truncated = False
                while not (terminated or truncated):
                    _, _, terminated, truncated, _ = env.step(expert.select_action())
                rows.append(
                    {
                        "task": task,
                        "seed": seed,
                        "success": env.is_success(),
                        "steps": env.steps,
                        "seconds": round(time.perf_counter() - start, 3),
                    }
                )
            done = [r for r in rows if r["task"] == task]
            print(f"{task}: {sum(r['success'] for r in done)}/{len(done)}", flush=True)
    finally:
        env.close()
    per_task = []
    for task in dict.fromkeys(r["task"] for r in rows):
        group = [r for r in rows if r["task"] == task]
        wins = [r for r in group if r["success"]]
        per_task.append(
            {
                "task": task,
                "episodes": len(group),
                "success_rate": len(wins) / len(group),
                "mean_steps_success": round(sum(r["steps"] for r in wins) / len(wins), 1) if wins else None,
                "s_per_episode": round(sum(r["seconds"] for r in group) / len(group), 2),
            }
        )
    overall = sum(r["success"] for r in rows) / len(rows)
    result = {"config": asdict(cfg), "per_task": per_task, "overall_success_rate": overall, "episodes": rows}
    out = Path(cfg.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2))
    return result


def _summary(cfg: MetaWorldExpertConfig, result: dict) -> None:
    print(f"\n{'task':22} {'success':>8} {'steps':>6} {'s/ep':>6}")
    for t in result["per_task"]:
        steps = "-" if t["mean_steps_success"] is None else f"{t['mean_steps_success']:.0f}"
        print(f"{t['task']:22} {t['success_rate']:>8.0%} {steps:>6} {t['s_per_episode']:>6.2f}")
    print(f"{'overall':22} {result['overall_success_rate']:>8.0%}  ({len(result['episodes'])} episodes)")
    print(f"wrote {cfg.output}")


def main(args: list[str] | None = None) -> dict:
    return cli_main(MetaWorldExpertConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
