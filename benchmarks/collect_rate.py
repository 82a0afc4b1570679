"""Collection throughput: successful demos per hour with four 224² cameras and two workers.

    python -m benchmarks.collect_rate [--episodes 30] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

from pipelines._cli import setup_environment
from pipelines.collect import CollectConfig, DatasetConfig, run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--size", type=int, default=224)
    args = parser.parse_args()
    setup_environment()
    root = Path(tempfile.mkdtemp(prefix="roboview_bench_")) / "ds"
    try:
        cfg = CollectConfig(dataset=DatasetConfig(repo_id="bench/demos", root=str(root), num_episodes=args.episodes,
                                                  image_size=args.size), num_workers=args.workers)
        result = run(cfg)
        print(json.dumps({"episodes": result.new_episodes, "attempts": result.attempts,
                          "failures": result.failures, "elapsed_s": round(result.elapsed_s, 1),
                          "demos_per_hour": round(result.demos_per_hour), "workers": args.workers,
                          "image_size": args.size, "cameras": 4}, indent=2))
    finally:
        shutil.rmtree(root.parent, ignore_errors=True)


if __name__ == "__main__":
    main()
