"""Coverage audit: which benchmark factor values a training dataset already showed its policy.

    roboview-coverage --dataset.root=outputs/demos --benchmark.path=outputs/benchmark \
        --output_dir=outputs/coverage [--color_radius=5] [--pose_radius_m=0.05] [--pose_angle_deg=5]

For every value of every visual split: `exact` (some training episode showed it), `nearby` (within
ΔE2000 `color_radius` in CIELAB, or within `pose_radius_m` and `pose_angle_deg` of camera pose) or
`never`, with the distance to the nearest episode (roboview.demos.coverage). Writes coverage.json,
coverage.md and coverage.png (training colors and camera positions against the test values).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from roboview.benchmark.format import load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.demos.coverage import STATUSES, Radii, load_training_visuals, summary
from roboview.demos.coverage_report import Coverage, write_coverage
from roboview.pipelines._cli import cli_main


@dataclass
class CoverageDatasetConfig:
    # Dataset folder written by roboview.pipelines.collect.
    root: str = ""


@dataclass
class CoverageBenchmarkConfig:
    # Benchmark folder written by roboview.pipelines.build_benchmark.
    path: str = "outputs/benchmark"
    # Comma-separated splits to audit (default: every split).
    splits: str = ""


@dataclass
class CoverageConfig:
    dataset: CoverageDatasetConfig = field(default_factory=CoverageDatasetConfig)
    benchmark: CoverageBenchmarkConfig = field(default_factory=CoverageBenchmarkConfig)
    # Folder for coverage.json, coverage.md and coverage.png.
    output_dir: str = "outputs/coverage"
    # A training color within this CIEDE2000 distance of a test color counts as nearby.
    color_radius: float = 5.0
    # A training camera within this distance (m) of a test pose (and within pose_angle_deg) counts as nearby.
    pose_radius_m: float = 0.05
    # A training camera within this rotation (deg) of a test pose (and within pose_radius_m) counts as nearby.
    pose_angle_deg: float = 5.0
    # Draw coverage.png.
    plots: bool = True

    def __post_init__(self) -> None:
        for name in ("color_radius", "pose_radius_m", "pose_angle_deg"):
            if not getattr(self, name) > 0:
                raise ValueError(f"--{name}={getattr(self, name)} must be positive")
        if not self.dataset.root:
            raise ValueError(
                "--dataset.root is required: a dataset folder written by roboview.pipelines.collect"
            )


def run(cfg: CoverageConfig) -> pd.DataFrame:
    with flag_errors("--dataset.root"):
        visuals = load_training_visuals(cfg.dataset.root)
    splits = [s.strip() for s in cfg.benchmark.splits.split(",") if s.strip()] or None
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path, splits)
    records = [item.record for items in bench.splits.values() for item in items]
    radii = Radii(cfg.color_radius, cfg.pose_radius_m, cfg.pose_angle_deg)
    coverage = Coverage.of(cfg.dataset.root, cfg.benchmark.path, bench.version, visuals, records, radii)
    write_coverage(coverage, Path(cfg.output_dir), cfg.plots)
    return coverage.table


def _summary(cfg: CoverageConfig, table: pd.DataFrame) -> None:
    counts = summary(table)
    for split, row in counts.iterrows():
        print(
            f"[coverage] {split}: "
            + ", ".join(f"{row[s]} {s}" for s in STATUSES)
            + (f", {row['unobserved']} unobserved" if row["unobserved"] else "")
        )
    print(
        f"[coverage] wrote coverage.json, coverage.md{', coverage.png' if cfg.plots else ''} to {cfg.output_dir}"
    )


def main(args: list[str] | None = None) -> pd.DataFrame:
    return cli_main(CoverageConfig, run, _summary, (ValueError,), args)


if __name__ == "__main__":
    main()
