"""Collection throughput: successful demos per hour with four 224² cameras and two workers.

python -m benchmarks.collect_rate [--episodes=30] [--workers=2] [--size=224]
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from roboview.pipelines._cli import cli_main
from roboview.pipelines.collect import CollectConfig, DatasetConfig
from roboview.pipelines.collect import run as collect


@dataclass
class CollectRateConfig:
    # Successful demos to collect.
    episodes: int = 30
    # Worker processes (spawned; one scene and renderer each).
    workers: int = 2
    # Side of the four cameras' square images (pixels).
    size: int = 224


def run(cfg: CollectRateConfig) -> dict:
    root = Path(tempfile.mkdtemp(prefix="roboview_bench_")) / "ds"
    try:
        collect_cfg = CollectConfig(
            dataset=DatasetConfig(
                repo_id="bench/demos", root=str(root), num_episodes=cfg.episodes, image_size=cfg.size
            ),
            num_workers=cfg.workers,
        )
        result = collect(collect_cfg)
        return {
            "episodes": result.new_episodes,
            "attempts": result.attempts,
            "failures": result.failures,
            "elapsed_s": round(result.elapsed_s, 1),
            "demos_per_hour": round(result.demos_per_hour),
            "workers": cfg.workers,
            "image_size": cfg.size,
            "cameras": 4,
        }
    finally:
        shutil.rmtree(root.parent, ignore_errors=True)


def _summary(cfg: CollectRateConfig, result: dict) -> None:
    print(json.dumps(result, indent=2))


def main(args: list[str] | None = None) -> dict:
    return cli_main(CollectRateConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
