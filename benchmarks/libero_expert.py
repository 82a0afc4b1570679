"""LIBERO scripted-expert success: the privileged expert over suites × tasks × init states, at baseline.

    python -m benchmarks.libero_expert [--suites=libero_object,libero_spatial] [--tasks=] [--init_states=0,1,2]
        [--seed=0] [--output=outputs/bench/libero_expert.json]

Why: the expert (roboview.libero.expert) is the policy-free reference of a LIBERO visual-bias study; this measures
how often it solves the unmodified scenes, with LeRobot's step budget (280 for both suites) and no camera rendered.
Each episode builds its own `LiberoWorld` (LeRobot's env, hard reset), so every number is a fresh LeRobot episode.
Writes a JSON (every episode, per-task and per-suite success, mean steps, seconds) and prints a table.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads
from roboview.libero.expert import EXPERT_SUITES


@dataclass
class LiberoExpertConfig:
    # Suites to run (libero_object and/or libero_spatial).
    suites: list[str] = field(default_factory=lambda: list(EXPERT_SUITES))
    # Task ids of each suite (empty: all ten).
    tasks: list[int] = field(default_factory=list)
    # Init state ids of each task.
    init_states: list[int] = field(default_factory=lambda: [0, 1, 2])
    # Seed handed to every reset (LIBERO seeds the global numpy RNG with it).
    seed: int = 0
    # Episode step budget (0: LeRobot's budget for the suite).
    max_steps: int = 0
    # JSON file the results are written to.
    output: str = "outputs/bench/libero_expert.json"


def _episode(suite: str, task_id: int, init_id: int, cfg: LiberoExpertConfig) -> dict:
    from roboview.libero import LiberoWorld, max_steps
    from roboview.libero.expert import run_episode

    start = time.perf_counter()
    with LiberoWorld(suite, task_id, init_id) as world:
        created = time.perf_counter() - start
        result = run_episode(world, cfg.max_steps or max_steps(suite), cfg.seed)
        reset_s = world.timings["reset_s"]
    row = {"suite": suite, "task_id": task_id, "init_state_id": init_id, **asdict(result)}
    row.update(create_s=round(created, 2), reset_s=round(reset_s, 2), seconds=round(result.seconds, 2))
    return row


def _summarize(rows: list[dict]) -> dict:
    def stats(group: list[dict]) -> dict:
        wins = [r for r in group if r["success"]]
        return {
            "episodes": len(group),
            "success_rate": len(wins) / len(group),
            "mean_steps_success": round(sum(r["steps"] for r in wins) / len(wins), 1) if wins else None,
            "s_per_episode": round(sum(r["seconds"] for r in group) / len(group), 2),
            "s_per_episode_with_setup": round(
                sum(r["seconds"] + r["create_s"] + r["reset_s"] for r in group) / len(group), 2
            ),
        }

    keys = sorted({(r["suite"], r["task_id"], r["name"]) for r in rows})
    per_task = [
        {
            "suite": s,
            "task_id": t,
            "name": n,
            **stats([r for r in rows if (r["suite"], r["task_id"]) == (s, t)]),
        }
        for s, t, n in keys
    ]
    per_suite = {s: stats([r for r in rows if r["suite"] == s]) for s in sorted({r["suite"] for r in rows})}
    return {"per_suite": per_suite, "per_task": per_task, "overall": stats(rows)}


def run(cfg: LiberoExpertConfig) -> dict:
    from roboview.libero import get_task, tasks

    bad = [s for s in cfg.suites if s not in EXPERT_SUITES]
    if bad:
        raise ValueError(f"--suites={','.join(bad)} not scripted; allowed: {', '.join(EXPERT_SUITES)}")
    rows = []
    for suite in cfg.suites:
        for task_id in cfg.tasks or range(len(tasks(suite))):
            name = get_task(suite, task_id).name
            for init_id in cfg.init_states:
                row = {"name": name, **_episode(suite, task_id, init_id, cfg)}
                rows.append(row)
                print(
                    f"{suite} task {task_id} init {init_id}: {'ok' if row['success'] else 'FAIL'} "
                    f"{row['steps']} steps, {row['seconds']} s (phase {row['phase']})",
                    flush=True,
                )
    result = {"config": asdict(cfg), **_summarize(rows), "episodes": rows}
    out = Path(cfg.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2))
    return result


def _summary(cfg: LiberoExpertConfig, result: dict) -> None:
    print(f"\n{'suite':15} {'task':>4} {'success':>8} {'steps':>6} {'s/ep':>6}  name")
    for t in result["per_task"]:
        steps = "-" if t["mean_steps_success"] is None else f"{t['mean_steps_success']:.0f}"
        print(
            f"{t['suite']:15} {t['task_id']:>4} {t['success_rate']:>8.0%} {steps:>6} "
            f"{t['s_per_episode']:>6.1f}  {t['name']}"
        )
    for suite, s in {**result["per_suite"], "overall": result["overall"]}.items():
        print(
            f"{suite:15} {'all':>4} {s['success_rate']:>8.0%} {s['mean_steps_success'] or '-':>6} "
            f"{s['s_per_episode']:>6.1f}  ({s['episodes']} episodes, {s['s_per_episode_with_setup']} s with setup)"
        )
    print(f"wrote {cfg.output}")


def main(args: list[str] | None = None) -> dict:
    return cli_main(LiberoExpertConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
