"""Episode tables → metrics.json, report.md, report.html and plots (the `roboview.pipelines.report` verb's library).

Input is one or several `episodes.parquet` files (docs/formats.md, "Episode records"): one per policy, or
one holding several policies. `load_results` validates them before any work — missing files, missing or null
columns, repeated episodes, and files evaluated on different benchmark versions (parquet
key-value metadata `roboview_benchmark_version`; a file without the key is not compared), and files
of another results format (`roboview_results_format`: seeds of the old per-instance rule) — so a
report never silently mixes incomparable runs.

metrics.json is `roboview.eval.statistics.metrics.compute_all_metrics` plus `sources` (path and benchmark version of
each file): for one policy the layout of docs/formats.md, for several {"epsilon", "resampling", "sources",
"policies": {name: layout}, "comparisons": [...]}. `write_report` writes it, then the plots
(roboview.eval.reporting.plots), report.md (roboview.eval.reporting.markdown) and report.html
(roboview.eval.reporting.html), both of which print only numbers read from that dict, so the files cannot
disagree.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from roboview.eval.reporting.html import HTML_FILE, render_html
from roboview.eval.reporting.markdown import markdown_sections, render_markdown
from roboview.eval.running import inputs, provenance, videos
from roboview.eval.running.agents import describe_agents
from roboview.eval.running.results import VERSION_KEY, ResultsError, counted, read_episodes, read_version
from roboview.eval.statistics.adaptive import read_record
from roboview.eval.statistics.context import context_breakdown
from roboview.eval.statistics.metrics import (
    METRIC_COLUMNS,
    EpisodesError,
    MetricsConfig,
    check_episodes,
    compute_all_metrics,
    policy_layouts,
)

log = logging.getLogger(__name__)

REQUIRED_COLUMNS = (*METRIC_COLUMNS, "repeat")
METRICS_FILE = "metrics.json"
REPORT_FILE = "report.md"


@dataclass(frozen=True)
class ReportResult:
    """What `write_report` produced, for the pipeline's summary line and for tests."""

    output_dir: Path
    metrics: dict[str, Any]
    plots: dict[str, str | None]  # file name → None when written, else why it was skipped


def load_results(
    paths: Sequence[str | Path], names: Sequence[str | None] | None = None
) -> tuple[pd.DataFrame, list[dict[str, Any]]]:
    """Read and validate episode tables; returns their concatenation and per-file provenance.

    `names[i]`, when given, renames the one policy of file i (two checkpoints evaluated under the
    same default name, say lerobot:act, become two policies). A results folder stands for its
    episodes.parquet. Raises FileNotFoundError naming missing files and EpisodesError, in one line naming
    the path and what was expected, for anything else: a benchmark folder or table, the journal
    episodes.jsonl, a CSV, bytes that are not parquet, unusable contents.
    """
    names = list(names) if names is not None else [None] * len(paths)
    paths = _results_files(paths)
    sources = [_source(p) for p in paths]
    tables = [_read(p) for p in paths]
    _check_one_version(sources)
    frames = []
    for path, name, frame, source in zip(paths, names, tables, sources):
        check_episodes(frame, REQUIRED_COLUMNS, source=str(path))
        if name:
            _rename(frame, name, path)
        if "video" in frame:  # paths relative to the results folder → absolute (the report links them)
            frame["video"] = frame["video"].map(lambda v, root=path.parent.resolve(): _absolute(v, root))
        frames.append(frame)
        source["policies"] = sorted(map(str, counted(frame)["policy"].unique()))
    episodes = pd.concat(frames, ignore_index=True)
    _check_no_repeats(episodes)
    return episodes, sources


def _results_files(paths: Sequence[str | Path]) -> list[Path]:
    """The episodes.parquet each given path stands for; EpisodesError or FileNotFoundError for what is none."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise EpisodesError("no results file given")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise FileNotFoundError(
            f"results file(s) not found: {', '.join(missing)}; expected the episodes.parquet "
            "that roboview.pipelines.evaluate writes into its --output_dir"
        )
    try:  # a results folder stands for its episodes.parquet; anything else that is not one is named
        return [inputs.results_file(p) for p in paths]
    except ValueError as exc:
        raise EpisodesError(str(exc)) from exc


def _source(path: Path) -> dict[str, Any]:
    """A results file's entry in metrics.json's `sources`: path, benchmark version, provenance, adaptive record."""
    return {
        "path": str(path),
        VERSION_KEY: read_version(path),
        "provenance": provenance.read(path.parent),
        **({"adaptive": rec} if (rec := read_record(path.parent)) else {}),
    }


def _read(path: Path) -> pd.DataFrame:
    """The episode rows of one results file (another results format: EpisodesError)."""
    try:
        return read_episodes(path)
    except ResultsError as exc:
        raise EpisodesError(str(exc)) from exc


def _check_one_version(sources: list[dict[str, Any]]) -> None:
    """EpisodesError unless every file that records its benchmark version records the same one."""
    versioned = [s for s in sources if s[VERSION_KEY] is not None]
    for s in versioned[1:]:
        if s[VERSION_KEY] != versioned[0][VERSION_KEY]:
            raise EpisodesError(
                f"results were evaluated on different benchmark versions: {versioned[0]['path']} has "
                f"{VERSION_KEY}={versioned[0][VERSION_KEY]!r}, {s['path']} has {s[VERSION_KEY]!r}; "
                "report runs of one benchmark version together"
            )


def _rename(frame: pd.DataFrame, name: str, path: Path) -> None:
    """Give the one policy of a file the name asked for (in place); EpisodesError when it holds several."""
    if counted(frame)["policy"].nunique() > 1:
        raise EpisodesError(
            f"{path} holds several policies ({', '.join(sorted(frame['policy'].unique()))}); "
            f"it cannot be renamed {name!r} as a whole"
        )
    frame["policy"] = name


def _absolute(video: Any, root: Path) -> str | None:
    """A row's comma-joined video paths, relative to its results folder `root`, made absolute (none: None)."""
    return ",".join(str(root / p) for p in video.split(",")) if isinstance(video, str) and video else None


def _check_no_repeats(episodes: pd.DataFrame) -> None:
    """EpisodesError when an episode (policy, instance, repeat) occurs twice: a file given twice, say."""
    dup = episodes.duplicated(["policy", "instance_id", "repeat"])
    if dup.any():
        row = episodes[dup].iloc[0]
        raise EpisodesError(
            f"{int(dup.sum())} episode(s) occur twice, e.g. policy {row['policy']!r} "
            f"instance {row['instance_id']!r} repeat {row['repeat']}; is a file given twice?"
        )


def video_index(episodes: pd.DataFrame, out: Path) -> dict[str, dict[str, dict[str, list[dict]]]]:
    """policy → split → value → [{label, cameras, paths (relative to the report folder)}] for filmed episodes."""
    if "video" not in episodes:
        return {}
    index: dict = {}
    filmed = episodes[episodes["video"].notna()].sort_values(
        ["policy", "split", "value", "instance_id", "repeat"]
    )
    for row in filmed.itertuples():
        files = row.video.split(",")
        label = f"{row.instance_id[:8]} r{row.repeat}{'' if row.success else ' ✗'}"
        index.setdefault(row.policy, {}).setdefault(row.split, {}).setdefault(str(row.value), []).append(
            {
                "label": label,
                "cameras": [videos.camera_of(f) for f in files],
                "paths": [os.path.relpath(f, out) for f in files],
            }
        )
    return index


def write_report(
    episodes: pd.DataFrame,
    output_dir: str | Path,
    cfg: MetricsConfig = MetricsConfig(),
    sources: list[dict[str, Any]] | None = None,
    plots: bool = True,
    metrics: dict[str, Any] | None = None,
) -> ReportResult:
    """Compute metrics, write metrics.json, the plots and report.md into `output_dir`. `metrics`: those
    `compute_all_metrics(episodes, cfg)` gives, already computed by the caller (completed here, in place)."""
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    if metrics is None:
        metrics = compute_all_metrics(episodes, cfg)
    if sources is not None:
        metrics["sources"] = sources
        _add_adaptive(metrics, sources)
    _add_episode_details(metrics, counted(episodes), cfg, out)
    (out / METRICS_FILE).write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    outcome: dict[str, str | None] = {}
    if plots:
        from roboview.eval.reporting.plots import (
            make_plots,  # matplotlib only when plots are asked for
        )

        outcome = make_plots(policy_layouts(metrics), out)
    sections = markdown_sections(metrics)  # report.md and report.html print the same sections
    (out / REPORT_FILE).write_text(render_markdown(metrics, outcome, sections))
    (out / HTML_FILE).write_text(render_html(metrics, outcome, out, sections))
    log.info(
        "wrote %s, %s, %s and %d plot(s) to %s",
        METRICS_FILE,
        REPORT_FILE,
        HTML_FILE,
        sum(r is None for r in outcome.values()),
        out,
    )
    return ReportResult(out, metrics, outcome)


def _add_adaptive(metrics: dict[str, Any], sources: list[dict[str, Any]]) -> None:
    """Adaptive runs: when and why each split stopped, into the split's metrics (files of one policy only)."""
    for source in sources:
        if source.get("adaptive") and len(source.get("policies", [])) == 1:
            layout = policy_layouts(metrics).get(source["policies"][0], {})
            for split, record in source["adaptive"]["splits"].items():
                if split in layout.get("splits", {}):
                    layout["splits"][split]["adaptive"] = record | {"design": source["adaptive"]["design"]}


def _add_episode_details(
    metrics: dict[str, Any], episodes: pd.DataFrame, cfg: MetricsConfig, out: Path
) -> None:
    """What the report reads from the counted episodes beyond the metrics: success by instruction, shape and
    initial position per policy, the VLM agents' columns, the filmed episodes (paths relative to `out`)."""
    for name, layout in policy_layouts(metrics).items():
        layout["context_factors"] = context_breakdown(episodes[episodes["policy"] == name], cfg)
    agents = describe_agents(episodes)
    if agents:
        metrics["agents"] = agents
    filmed = video_index(episodes, out.resolve())
    if filmed:
        metrics["videos"] = filmed
