"""Episode tables → metrics.json, report.md and plots (the `pipelines.report` verb's library).

Input is one or several `episodes.parquet` files (DESIGN.md, "Episode record"): one per policy, or
one holding several policies. They are validated before any work — missing files, missing or null
columns, repeated episodes, and files evaluated on different benchmark versions (parquet
key-value metadata `roboview_benchmark_version`; a file without the key is not compared) — so a
report never silently mixes incomparable runs.

metrics.json is `eval.metrics.compute_all_metrics` plus `sources` (path and benchmark version of
each file): for one policy DESIGN's layout, for several {"epsilon", "resampling", "sources",
"policies": {name: layout}}. report.md prints only numbers read from that dict — SR, CV and IEC
×100 as in the paper's Tables 1 and 2, p-values as they are — so the two files cannot disagree.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow.parquet as pq

from eval.metrics import (
    METRIC_COLUMNS, EpisodesError, MetricsConfig, check_episodes, compute_all_metrics, policy_layouts,
)
from roboview_data.factors import VISUAL_FACTORS

log = logging.getLogger(__name__)

VERSION_KEY = "roboview_benchmark_version"
REQUIRED_COLUMNS = (*METRIC_COLUMNS, "repeat")
METRICS_FILE = "metrics.json"
REPORT_FILE = "report.md"
_TITLES = {"color": "Color", "camera_pose": "Camera Pose", "camera_euler": "Camera Euler",
           "dist_scale": "Dist Scale"}
_N_EXTREMES = 3  # values listed at each end of the per-value deviation ranking


@dataclass(frozen=True)
class ReportResult:
    """What `write_report` produced, for the pipeline's summary line and for tests."""

    output_dir: Path
    metrics: dict[str, Any]
    plots: dict[str, str | None]  # file name → None when written, else why it was skipped


def read_version(path: Path) -> str | None:
    """The file's `roboview_benchmark_version` parquet metadata, None when it has none."""
    meta = pq.read_schema(path).metadata or {}
    raw = meta.get(VERSION_KEY.encode())
    return None if raw is None else raw.decode()


def load_results(paths: Sequence[str | Path]) -> tuple[pd.DataFrame, list[dict[str, Any]]]:
    """Read and validate episode tables; returns their concatenation and per-file provenance.

    Raises FileNotFoundError naming missing files and EpisodesError for unusable contents.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise EpisodesError("no results file given")
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"results file(s) not found: {', '.join(missing)}")
    sources = [{"path": str(p), VERSION_KEY: read_version(p)} for p in paths]
    versioned = [s for s in sources if s[VERSION_KEY] is not None]
    for s in versioned[1:]:
        if s[VERSION_KEY] != versioned[0][VERSION_KEY]:
            raise EpisodesError(
                f"results were evaluated on different benchmark versions: {versioned[0]['path']} has "
                f"{VERSION_KEY}={versioned[0][VERSION_KEY]!r}, {s['path']} has {s[VERSION_KEY]!r}; "
                "report runs of one benchmark version together")
    frames = []
    for path in paths:
        frame = pd.read_parquet(path)
        check_episodes(frame, REQUIRED_COLUMNS, source=str(path))
        frames.append(frame)
    episodes = pd.concat(frames, ignore_index=True)
    dup = episodes.duplicated(["policy", "instance_id", "repeat"])
    if dup.any():
        row = episodes[dup].iloc[0]
        raise EpisodesError(f"{int(dup.sum())} episode(s) occur twice, e.g. policy {row['policy']!r} "
                         f"instance {row['instance_id']!r} repeat {row['repeat']}; is a file given twice?")
    return episodes, sources


def pct(x: float | None) -> str:
    """A ratio ×100 with two decimals, the paper's table convention; N/A for null."""
    return "N/A" if x is None else f"{100 * x:.2f}"


def pct_ci(ci: Sequence[float] | None) -> str:
    return "" if ci is None else f" [{pct(ci[0])}, {pct(ci[1])}]"


def p_fmt(p: float | None) -> str:
    return "N/A" if p is None else f"{p:.4f}"


def _row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return [_row(header), _row(["---"] * len(header)), *(_row(r) for r in rows), ""]


def _split_order(layouts: dict[str, dict], key: str) -> list[str]:
    present = {s for layout in layouts.values() for s in layout[key]}
    return [s for s in VISUAL_FACTORS if s in present] + sorted(present - set(VISUAL_FACTORS))


def _bold_min(rows: list[list[str]], values: list[list[float | None]]) -> None:
    """Bold the lowest CV/IEC of each column, as the paper marks the least biased agent."""
    if len(rows) < 2:
        return
    for j in range(len(values[0])):
        column = [(v[j], i) for i, v in enumerate(values) if v[j] is not None]
        if column:
            i = min(column)[1]
            rows[i][j + 1] = f"**{rows[i][j + 1]}**"


def _table1(layouts: dict[str, dict]) -> list[str]:
    splits = _split_order(layouts, "splits")
    header = ["Policy", *(f"{_TITLES.get(s, s)} {m}" for s in splits for m in ("SR", "CV")), "Average SR", "Average CV"]
    rows, cvs = [], []
    for name, layout in layouts.items():
        row, cv_row = [name], []
        for s in splits:
            m = layout["splits"].get(s)
            row += ["—", "—"] if m is None else [pct(m["sr"]) + pct_ci(m["sr_ci95"]),
                                                 pct(m["cv"]) + pct_ci(m["cv_ci95"])]
            cv_row += [None, None if m is None else m["cv"]]
        row += [pct(layout["average"]["sr"]), pct(layout["average"]["cv"])]
        rows.append(row)
        cvs.append(cv_row + [None, layout["average"]["cv"]])
    _bold_min(rows, cvs)
    return ["## Table 1 — success rate and Bias Coefficient (×100, 95 % CI)", "",
            *_table(header, rows),
            "SR: mean success over a split's episodes, Wilson interval. CV: mean over contexts of "
            "σ_v SR(v,c) / (μ_v SR(v,c) + ε), bootstrap interval over repeats. N/A: every episode "
            "failed. Bold: lowest CV.", ""]


def _table2(layouts: dict[str, dict]) -> list[str]:
    lines: list[str] = []
    for split in _split_order(layouts, "interactions"):
        have = {n: lay["interactions"][split] for n, lay in layouts.items() if split in lay["interactions"]}
        a, b = next(iter(have.values()))["factors"]
        header = ["Policy", "SR", f"CV_SR({a})", f"IEC({a}; {b})", f"CV_SR({b})", f"IEC({b}; {a})"]
        rows, values = [], []
        for name, m in have.items():
            keys = [("cv", a), ("iec", f"{a}|{b}"), ("cv", b), ("iec", f"{b}|{a}")]
            rows.append([name, pct(m["sr"]) + pct_ci(m["sr_ci95"])]
                        + [pct(m[k][x]) + pct_ci(m[f"{k}_ci95"][x]) for k, x in keys])
            values.append([None] + [m[k][x] for k, x in keys])
        _bold_min(rows, values)
        lines += [f"## Table 2 — {split}: Bias Coefficient and Interaction Effect Coefficient (×100, 95 % CI)", "",
                  *_table(header, rows),
                  f"IEC({a}; {b}): how much the bias from {a} changes with {b} (mean over contexts of "
                  f"σ_b CV({a}|b,c) / (μ_b CV({a}|b,c) + ε)). Bold: lowest.", ""]
    return lines


def _tests_table(layouts: dict[str, dict]) -> list[str]:
    splits, inter = _split_order(layouts, "splits"), _split_order(layouts, "interactions")
    factors = {s: next(lay["interactions"][s]["factors"] for lay in layouts.values() if s in lay["interactions"])
               for s in inter}
    header = ["Policy", *splits, *(f"{s}: {f}" for s in inter for f in factors[s])]
    rows = []
    for name, layout in layouts.items():
        row = [name] + [p_fmt(layout["splits"][s]["p_value"]) if s in layout["splits"] else "—" for s in splits]
        for s in inter:
            m = layout["interactions"].get(s)
            row += [p_fmt(m["p_value"][f]) if m else "—" for f in factors[s]]
        rows.append(row)
    return ["## Does success depend on the factor? (permutation p-values)", "", *_table(header, rows),
            "Value labels are shuffled among the episodes of each context (of each (other value, "
            "context) in a factorial split); statistic: the Bias Coefficient.", ""]


def _diagnostics(layouts: dict[str, dict]) -> list[str]:
    rows = []
    for name, layout in layouts.items():
        for split, m in layout["splits"].items():
            rows.append([name, split, str(m["n_instances"]), str(m["n_episodes"]), pct(m["cv_bias"])])
        for split, m in layout["interactions"].items():
            for f in m["factors"]:
                rows.append([name, f"{split}: {f}", str(m["n_instances"]), str(m["n_episodes"]), pct(m["cv_bias"][f])])
    return ["## Sample sizes and repeat-noise bias of CV", "",
            *_table(["Policy", "Split", "Instances", "Episodes", "CV bias ×100"], rows),
            "CV bias: mean bootstrap CV minus reported CV. Repeat noise inflates CV; a large bias "
            "means more repeats are needed before CVs are compared.", ""]


def _extremes(layouts: dict[str, dict]) -> list[str]:
    lines = ["## Values furthest from their context mean (signed deviation ×100; SR ×100)", ""]
    for name, layout in layouts.items():
        for split, m in layout["splits"].items():
            ranked = sorted(m["per_value"].items(), key=lambda kv: kv[1]["signed_dev"])
            text = [f"{v} ({pct(s['signed_dev'])}; SR {pct(s['sr'])})" for v, s in ranked]
            if len(text) > 2 * _N_EXTREMES:
                text = [*text[:_N_EXTREMES], "…", *text[-_N_EXTREMES:]]
            lines.append(f"- {name}, {split}, lowest to highest: {', '.join(text)}")
    return [*lines, ""]


def render_markdown(metrics: dict[str, Any], plots: dict[str, str | None]) -> str:
    """report.md from a metrics dict (every number printed is read from it) and plot outcomes."""
    layouts = policy_layouts(metrics)
    settings = metrics["resampling"]
    lines = ["# RoboView-Bias report", "",
             f"Policies: {', '.join(layouts)}. ε = {metrics['epsilon']:g}; {settings['n_boot']} bootstrap "
             f"replicates, {settings['n_perm']} permutations, seed {settings['seed']}.", ""]
    for source in metrics.get("sources", []):
        lines.append(f"- source `{source['path']}` (benchmark version {source[VERSION_KEY] or 'not recorded'})")
    lines.append("")
    lines += _table1(layouts) + _table2(layouts) + _tests_table(layouts) + _diagnostics(layouts) + _extremes(layouts)
    lines += ["## Plots", ""]
    for name, reason in plots.items():
        lines.append(f"![{name}]({name})" if reason is None else f"- {name} skipped: {reason}")
    return "\n".join(lines) + "\n"


def write_report(episodes: pd.DataFrame, output_dir: str | Path, cfg: MetricsConfig = MetricsConfig(),
                 sources: list[dict[str, Any]] | None = None, plots: bool = True) -> ReportResult:
    """Compute metrics, write metrics.json, the plots and report.md into `output_dir`."""
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = compute_all_metrics(episodes, cfg)
    if sources is not None:
        metrics["sources"] = sources
    (out / METRICS_FILE).write_text(json.dumps(metrics, indent=2) + "\n")
    outcome: dict[str, str | None] = {}
    if plots:
        from eval.report_plots import make_plots  # matplotlib only when plots are asked for

        outcome = make_plots(policy_layouts(metrics), out)
    (out / REPORT_FILE).write_text(render_markdown(metrics, outcome))
    log.info("wrote %s, %s and %d plot(s) to %s", METRICS_FILE, REPORT_FILE,
             sum(r is None for r in outcome.values()), out)
    return ReportResult(out, metrics, outcome)
