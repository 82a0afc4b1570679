"""Evaluation throughput with 1 and 2 workers, and where one worker's time goes.

    python -m benchmarks.eval_rate [--benchmark outputs/benchmark] [--limit 12] [--policy vision]
    python -m benchmarks.eval_rate --policy lerobot --path CKPT/pretrained_model [--split camera_pose]

Builds the tiny benchmark if none is given, evaluates the same episodes with 1 and 2 local workers
(the policy's own cameras and image size; a checkpoint's, for lerobot; ≤ 120 control steps) and
prints the rates and their ratio. Then, in this process, it runs the same episodes once more through
one `EvalWorker` with timers around the env's camera rendering, the policy's `select_action` and
the rest of `env.step` (MuJoCo physics and the success check), and prints each one's share of the
episode time. The episodes are those of `--split` (default: every split), first `--limit` of each.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from pipelines._cli import setup_environment
from pipelines.build_benchmark import BuildConfig
from pipelines.build_benchmark import run as build
from pipelines.evaluate import (
    BenchmarkConfig,
    EvalConfig,
    EvaluateConfig,
    resolve_image_size,
    run,
)
from policies.base import PolicyConfig, policy_config


def _timed(totals: dict[str, float], key: str, fn):
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            totals[key] += time.perf_counter() - start
    return wrapper


def breakdown(bench: str, policy: PolicyConfig, splits: str, limit: int) -> dict:
    """Seconds per episode in render, inference and physics (+ other), one worker, one thread pool."""
    import os

    from eval.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview_data.benchmark.format import load_benchmark

    worker = EvalWorker(WorkerSpec(policy, resolve_image_size(policy, 0), torch_threads=os.cpu_count() or 1))
    totals: dict[str, float] = defaultdict(float)
    env = worker.env
    env.render_camera = _timed(totals, "render", env.render_camera)
    worker.policy.select_action = _timed(totals, "inference", worker.policy.select_action)
    env.step = _timed(totals, "step_incl_render", env.step)
    items = [i for its in load_benchmark(bench, [s for s in splits.split(",") if s] or None).splits.values()
             for i in its[:limit]]
    steps, start = 0, time.perf_counter()
    for item in items:
        steps += worker.run(WorkItem(item, 0)).row["steps"]
    total = time.perf_counter() - start
    # Rendering happens in reset and in step; physics is step time minus its rendering.
    render_in_step = totals["render"] * steps / (steps + len(items))
    parts = {"render": totals["render"], "inference": totals["inference"],
             "physics": totals["step_incl_render"] - render_in_step}
    parts["other"] = total - sum(parts.values())
    worker.close()
    return {"episodes": len(items), "steps": steps, "seconds_per_episode": round(total / len(items), 3),
            "ms_per_step": round(1000 * total / steps, 2),
            "share": {k: round(v / total, 3) for k, v in parts.items()},
            "ms_per_step_by_part": {k: round(1000 * v / steps, 2) for k, v in parts.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--benchmark", default="")
    parser.add_argument("--limit", type=int, default=12, help="episodes per split")
    parser.add_argument("--policy", default="vision")
    parser.add_argument("--path", default=None, help="checkpoint folder for --policy lerobot")
    parser.add_argument("--split", default="", help="comma-separated splits (default: all)")
    args = parser.parse_args()
    setup_environment()
    policy = policy_config(args.policy, **({"path": args.path} if args.path else {}))
    scratch = Path(tempfile.mkdtemp(prefix="roboview_evalrate_"))
    try:
        bench = args.benchmark or str(scratch / "bench")
        if not args.benchmark:
            build(BuildConfig(output_dir=bench, preset="tiny", image_size=96))
        rates = {}
        for workers in (1, 2):
            cfg = EvaluateConfig(BenchmarkConfig(bench, args.split), policy,
                                 EvalConfig(n_repeats=1, limit=args.limit, num_workers=workers),
                                 str(scratch / f"w{workers}"))
            result = run(cfg)
            rates[workers] = {"episodes": result.new_episodes, "elapsed_s": round(result.elapsed_s, 1),
                              "episodes_per_hour": round(result.episodes_per_hour),
                              "success_rate": round(result.success_rate, 3)}
        print(json.dumps({"policy": args.policy, "path": args.path, "by_workers": rates,
                          "speedup_2_vs_1": round(rates[2]["episodes_per_hour"] / rates[1]["episodes_per_hour"], 2),
                          "one_worker_time": breakdown(bench, policy, args.split, args.limit)}, indent=2))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
