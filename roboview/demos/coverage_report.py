"""A coverage audit's files (roboview.demos.coverage measures it): coverage.json (every value's status and
distance, the counts per split), coverage.md (the counts and the values training showed) and coverage.png (the
training colors and camera positions against the test values)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.demos.coverage import Radii, TrainingVisuals, audit, summary

MARKERS = {"exact": "*", "nearby": "o", "never": "x", "unobserved": "."}
CAMERA_SPLITS = (("camera_pose", "tab:blue"), ("camera_euler", "tab:green"), ("dist_scale", "tab:red"))


@dataclass(frozen=True)
class Coverage:
    """A coverage audit: the dataset and benchmark audited, the training visuals, the benchmark's records, the
    radii and the per-value table (roboview.demos.coverage.audit)."""

    dataset: str
    benchmark: str
    benchmark_version: str
    visuals: TrainingVisuals
    records: list[dict]
    radii: Radii
    table: pd.DataFrame

    @classmethod
    def of(
        cls,
        dataset: str,
        benchmark: str,
        version: str,
        visuals: TrainingVisuals,
        records: list[dict],
        radii: Radii,
    ) -> Coverage:
        """Audit the benchmark's records (read from `benchmark`, version `version`) against the visuals of the
        dataset at `dataset`."""
        return cls(dataset, benchmark, version, visuals, records, radii, audit(visuals, records, radii))


def write_coverage(coverage: Coverage, out: Path, plots: bool = True) -> None:
    """coverage.json, coverage.md and (with `plots`) coverage.png in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "coverage.json").write_text(json.dumps(coverage_json(coverage), indent=1))
    (out / "coverage.md").write_text(coverage_markdown(coverage))
    if plots:
        plot_coverage(coverage, out / "coverage.png")


def coverage_json(coverage: Coverage) -> dict:
    """coverage.json's content."""
    visuals, radii, table = coverage.visuals, coverage.radii, coverage.table
    return {
        "dataset": coverage.dataset,
        "benchmark_version": coverage.benchmark_version,
        "episodes": visuals.n,
        "randomized": list(visuals.randomized),
        "camera": visuals.camera,
        "radii": {"color_delta_e": radii.color_delta_e, "pose_m": radii.pose_m, "pose_deg": radii.pose_deg},
        "summary": {split: {k: int(v) for k, v in row.items()} for split, row in summary(table).iterrows()},
        "values": json.loads(table.to_json(orient="records")),
    }


def coverage_markdown(coverage: Coverage) -> str:
    """coverage.md: the counts per split and the values training showed."""
    visuals, radii, table = coverage.visuals, coverage.radii, coverage.table
    lines = [
        f"# Coverage of {coverage.benchmark} by {coverage.dataset}",
        "",
        f"{visuals.n} training episodes; randomized: {', '.join(visuals.randomized) or 'nothing (context-only)'}; "
        f"camera audited: {visuals.camera or 'none (no perturbed camera recorded)'}. Nearby = "
        f"ΔE2000 ≤ {radii.color_delta_e:g}, camera ≤ {radii.pose_m:g} m and ≤ {radii.pose_deg:g}°.",
        "",
        "| split | exact | nearby | never | unobserved | test contexts seen in training |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for split, row in summary(table).iterrows():
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


def plot_coverage(coverage: Coverage, path: Path) -> None:
    """coverage.png: the test colors (CIELAB a*–b*) and camera positions (top view) by status, over training's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = coverage.table
    by_key = {(r["split"], r["value"]): r for r in coverage.records}
    status = dict(zip(zip(table["split"], table["value"]), table["status"]))
    fig, (ax_c, ax_p) = plt.subplots(1, 2, figsize=(11, 5))
    _color_panel(ax_c, coverage.visuals, by_key, status)
    if coverage.visuals.camera is not None:
        _camera_panel(ax_p, coverage.visuals, by_key, status)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _color_panel(ax, visuals: TrainingVisuals, by_key: dict, status: dict) -> None:
    ax.scatter(visuals.lab[:, 1], visuals.lab[:, 2], s=6, c="0.6", label=f"training ({visuals.n} episodes)")
    colors = [(k, r) for k, r in by_key.items() if r["split"] == "color"]
    for st, marker in MARKERS.items():
        pts = [(r["color_lab"], r["color_rgb"]) for k, r in colors if status[k] == st]
        if pts:
            lab, rgb = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
            ax.scatter(
                lab[:, 1],
                lab[:, 2],
                s=40,
                c=rgb,
                marker=marker,
                edgecolors="k" if marker not in "x." else None,
                linewidths=0.4,
                label=f"test color: {st} ({len(pts)})",
            )
    ax.set(xlabel="a*", ylabel="b*", title="Object color (CIELAB a*–b*)")
    ax.legend(fontsize=7, loc="lower left")


def _camera_panel(ax, visuals: TrainingVisuals, by_key: dict, status: dict) -> None:
    ax.scatter(visuals.pos[:, 0], visuals.pos[:, 1], s=6, c="0.6", label="training")
    for split, color in CAMERA_SPLITS:
        for st, marker in MARKERS.items():
            pts = [
                next(c["pos"] for c in r["cameras"] if c["name"] == visuals.camera)
                for k, r in by_key.items()
                if r["split"] == split and status[k] == st
            ]
            if pts:
                pts = np.array(pts)
                ax.scatter(
                    pts[:, 0], pts[:, 1], s=40, marker=marker, c=color, label=f"{split}: {st} ({len(pts)})"
                )
    ax.set(xlabel="x (m)", ylabel="y (m)", title=f"Camera '{visuals.camera}' position (top view)")
    ax.set_aspect("equal")
    ax.legend(fontsize=7, loc="best")
