"""Evaluation throughput: episodes per hour of the `vision` agent with 1 and with 2 workers.

    python -m benchmarks.eval_rate [--benchmark outputs/benchmark] [--limit 12] [--policy vision]

Builds the tiny benchmark if none is given, evaluates the same episodes with 1 and 2 local workers
(224², ≤ 120 control steps, two cameras rendered: the agent's RGB-D camera) and prints the rates
and their ratio.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

from pipelines._cli import setup_environment
from pipelines.build_benchmark import BuildConfig
from pipelines.build_benchmark import run as build
from pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, PolicyConfig, run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--benchmark", default="")
    parser.add_argument("--limit", type=int, default=12)
    parser.add_argument("--policy", default="vision")
    args = parser.parse_args()
    setup_environment()
    scratch = Path(tempfile.mkdtemp(prefix="roboview_evalrate_"))
    try:
        bench = args.benchmark or str(scratch / "bench")
        if not args.benchmark:
            build(BuildConfig(output_dir=bench, preset="tiny", image_size=96))
        rates = {}
        for workers in (1, 2):
            cfg = EvaluateConfig(BenchmarkConfig(bench), PolicyConfig(args.policy),
                                 EvalConfig(n_repeats=1, limit=args.limit, num_workers=workers),
                                 str(scratch / f"w{workers}"))
            result = run(cfg)
            rates[workers] = {"episodes": result.new_episodes, "elapsed_s": round(result.elapsed_s, 1),
                              "episodes_per_hour": round(result.episodes_per_hour),
                              "success_rate": round(result.success_rate, 3)}
        print(json.dumps({"policy": args.policy, "by_workers": rates,
                          "speedup_2_vs_1": round(rates[2]["episodes_per_hour"] / rates[1]["episodes_per_hour"], 2)},
                         indent=2))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
