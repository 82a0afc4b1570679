"""Coverage audit: which benchmark factor values a training dataset already showed its policy.

    roboview-coverage --dataset.root=outputs/demos --benchmark.path=outputs/benchmark \
        --output_dir=outputs/coverage [--color_radius=5] [--pose_radius_m=0.05] [--pose_angle_deg=5]

For every value of every visual split: `exact` (some training episode showed it), `nearby` (within
ΔE2000 `color_radius` in CIELAB, or within `pose_radius_m` and `pose_angle_deg` of camera pose) or
`never`, with the distance to the nearest episode (roboview.demos.coverage). Writes coverage.json,
coverage.md and coverage.png (training colors and camera positions against the test values).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.benchmark.format import load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.demos.coverage import (
    STATUSES,
    Radii,
    TrainingVisuals,
    audit,
    load_training_visuals,
    summary,
)
from roboview.pipelines._cli import cli_main

log = logging.getLogger(__name__)


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


def _plot(visuals: TrainingVisuals, table: pd.DataFrame, records: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    markers = {"exact": "*", "nearby": "o", "never": "x", "unobserved": "."}
    fig, (ax_c, ax_p) = plt.subplots(1, 2, figsize=(11, 5))
    ax_c.scatter(visuals.lab[:, 1], visuals.lab[:, 2], s=6, c="0.6", label=f"training ({visuals.n} episodes)")
    by_key = {(r["split"], r["value"]): r for r in records}
    status = dict(zip(zip(table["split"], table["value"]), table["status"]))
    colors = [(k, r) for k, r in by_key.items() if r["split"] == "color"]
    for st, marker in markers.items():
        pts = [(r["color_lab"], r["color_rgb"]) for k, r in colors if status[k] == st]
        if pts:
            lab, rgb = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
            ax_c.scatter(
                lab[:, 1],
                lab[:, 2],
                s=40,
                c=rgb,
                marker=marker,
                edgecolors="k" if marker not in "x." else None,
                linewidths=0.4,
                label=f"test color: {st} ({len(pts)})",
            )
    ax_c.set(xlabel="a*", ylabel="b*", title="Object color (CIELAB a*–b*)")
    ax_c.legend(fontsize=7, loc="lower left")
    if visuals.camera is not None:
        ax_p.scatter(visuals.pos[:, 0], visuals.pos[:, 1], s=6, c="0.6", label="training")
        for split, color in (
            ("camera_pose", "tab:blue"),
            ("camera_euler", "tab:green"),
            ("dist_scale", "tab:red"),
        ):
            for st, marker in markers.items():
                pts = [
                    next(c["pos"] for c in r["cameras"] if c["name"] == visuals.camera)
                    for k, r in by_key.items()
                    if r["split"] == split and status[k] == st
                ]
                if pts:
                    pts = np.array(pts)
                    ax_p.scatter(
                        pts[:, 0],
                        pts[:, 1],
                        s=40,
                        marker=marker,
                        c=color,
                        label=f"{split}: {st} ({len(pts)})",
                    )
        ax_p.set(xlabel="x (m)", ylabel="y (m)", title=f"Camera '{visuals.camera}' position (top view)")
        ax_p.set_aspect("equal")
        ax_p.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _markdown(cfg: CoverageConfig, visuals: TrainingVisuals, table: pd.DataFrame) -> str:
    counts = summary(table)
    lines = [
        f"# Coverage of {cfg.benchmark.path} by {cfg.dataset.root}",
        "",
        f"{visuals.n} training episodes; randomized: {', '.join(visuals.randomized) or 'nothing (context-only)'}; "
        f"camera audited: {visuals.camera or 'none (no perturbed camera recorded)'}. Nearby = "
        f"ΔE2000 ≤ {cfg.color_radius:g}, camera ≤ {cfg.pose_radius_m:g} m and ≤ {cfg.pose_angle_deg:g}°.",
        "",
        "| split | exact | nearby | never | unobserved | test contexts seen in training |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for split, row in counts.iterrows():
        ctx = table.loc[table["split"] == split, "contexts_in_training"].mean()
        lines.append(
            f"| {split} | {row['exact']} | {row['nearby']} | {row['never']} | {row['unobserved']} "
            f"| {ctx:.0%} |"
        )
    lines += ["", "## Values seen in training (exact or nearby)", ""]
    seen = table[table["status"].isin(("exact", "nearby"))]
    for split, group in seen.groupby("split", sort=False):
        lines.append(
            f"- **{split}**: " + ", ".join(f"{v} ({s})" for v, s in zip(group["value"], group["status"]))
        )
    if seen.empty:
        lines.append("None.")
    return "\n".join(lines) + "\n"


def run(cfg: CoverageConfig) -> pd.DataFrame:
    with flag_errors("--dataset.root"):
        visuals = load_training_visuals(cfg.dataset.root)
    splits = [s.strip() for s in cfg.benchmark.splits.split(",") if s.strip()] or None
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path, splits)
    records = [item.record for items in bench.splits.values() for item in items]
    table = audit(visuals, records, Radii(cfg.color_radius, cfg.pose_radius_m, cfg.pose_angle_deg))
    out = Path(cfg.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    payload = {
        "dataset": cfg.dataset.root,
        "benchmark_version": bench.version,
        "episodes": visuals.n,
        "randomized": list(visuals.randomized),
        "camera": visuals.camera,
        "radii": {
            "color_delta_e": cfg.color_radius,
            "pose_m": cfg.pose_radius_m,
            "pose_deg": cfg.pose_angle_deg,
        },
        "summary": {split: {k: int(v) for k, v in row.items()} for split, row in summary(table).iterrows()},
        "values": json.loads(table.to_json(orient="records")),
    }
    (out / "coverage.json").write_text(json.dumps(payload, indent=1))
    (out / "coverage.md").write_text(_markdown(cfg, visuals, table))
    if cfg.plots:
        _plot(visuals, table, records, out / "coverage.png")
    return table


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
