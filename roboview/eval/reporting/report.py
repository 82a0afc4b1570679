"""Episode tables → metrics.json, report.md, report.html and plots (the `roboview.pipelines.report` verb's library).

Input is one or several `episodes.parquet` files (docs/formats.md, "Episode records"): one per policy, or
one holding several policies. They are validated before any work — missing files, missing or null
columns, repeated episodes, and files evaluated on different benchmark versions (parquet
key-value metadata `roboview_benchmark_version`; a file without the key is not compared), and files
of another results format (`roboview_results_format`: seeds of the old per-instance rule) — so a
report never silently mixes incomparable runs.

metrics.json is `roboview.eval.statistics.metrics.compute_all_metrics` plus `sources` (path and benchmark version of
each file): for one policy the layout of docs/formats.md, for several {"epsilon", "resampling", "sources",
"policies": {name: layout}, "comparisons": [...]}. report.md prints only numbers read from that dict —
SR, CV, cv_excess and IEC ×100 as in the paper's Tables 1 and 2, p-values as they are — so the two
files cannot disagree.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.reporting.format import (
    ALPHA,
    directions,
    p_fmt,
    pct,
    pct_ci,
    policy_label,
    resampling_line,
    split_order,
    split_title,
)
from roboview.eval.reporting.html import HTML_FILE, render_html
from roboview.eval.reporting.tables import (
    POLICY,
    SPLIT_COLUMNS,
    VIDEO_COLUMNS,
    Table,
    markdown_table,
    split_table,
    summary_table,
    to_markdown,
    video_splits,
    videos_table,
)
from roboview.eval.running import inputs, provenance, videos
from roboview.eval.running.agents import agents_markdown, describe_agents
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
from roboview.variation.factors import visual_factors
from roboview.variation.instances import split_task

log = logging.getLogger(__name__)

REQUIRED_COLUMNS = (*METRIC_COLUMNS, "repeat")
METRICS_FILE = "metrics.json"
REPORT_FILE = "report.md"
_N_EXTREMES = 3  # values listed at each end of the per-value deviation ranking


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
    paths = [Path(p) for p in paths]
    names = list(names) if names is not None else [None] * len(paths)
    if not paths:
        raise EpisodesError("no results file given")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise FileNotFoundError(
            f"results file(s) not found: {', '.join(missing)}; expected the episodes.parquet "
            "that roboview.pipelines.evaluate writes into its --output_dir"
        )
    try:  # a results folder stands for its episodes.parquet; anything else that is not one is named
        paths = [inputs.results_file(p) for p in paths]
    except ValueError as exc:
        raise EpisodesError(str(exc)) from exc
    sources = [
        {
            "path": str(p),
            VERSION_KEY: read_version(p),
            "provenance": provenance.read(p.parent),
            **({"adaptive": rec} if (rec := read_record(p.parent)) else {}),
        }
        for p in paths
    ]
    tables = []
    for path in paths:
        try:
            tables.append(read_episodes(path))
        except ResultsError as exc:
            raise EpisodesError(str(exc)) from exc
    versioned = [s for s in sources if s[VERSION_KEY] is not None]
    for s in versioned[1:]:
        if s[VERSION_KEY] != versioned[0][VERSION_KEY]:
            raise EpisodesError(
                f"results were evaluated on different benchmark versions: {versioned[0]['path']} has "
                f"{VERSION_KEY}={versioned[0][VERSION_KEY]!r}, {s['path']} has {s[VERSION_KEY]!r}; "
                "report runs of one benchmark version together"
            )
    frames = []
    for path, name, frame in zip(paths, names, tables):
        check_episodes(frame, REQUIRED_COLUMNS, source=str(path))
        if name:
            if counted(frame)["policy"].nunique() > 1:
                raise EpisodesError(
                    f"{path} holds several policies ({', '.join(sorted(frame['policy'].unique()))}); "
                    f"it cannot be renamed {name!r} as a whole"
                )
            frame["policy"] = name
        if "video" in frame:  # paths relative to the results folder → absolute (the report links them)
            frame["video"] = frame["video"].map(
                lambda v, root=path.parent.resolve(): (
                    ",".join(str(root / p) for p in v.split(",")) if isinstance(v, str) and v else None
                )
            )
        frames.append(frame)
        source = sources[len(frames) - 1]
        source["policies"] = sorted(map(str, counted(frame)["policy"].unique()))
    episodes = pd.concat(frames, ignore_index=True)
    dup = episodes.duplicated(["policy", "instance_id", "repeat"])
    if dup.any():
        row = episodes[dup].iloc[0]
        raise EpisodesError(
            f"{int(dup.sum())} episode(s) occur twice, e.g. policy {row['policy']!r} "
            f"instance {row['instance_id']!r} repeat {row['repeat']}; is a file given twice?"
        )
    return episodes, sources


def _noise_floor_line(layouts: dict[str, dict]) -> list[str]:
    floor_only = [
        f"{name}/{split}"
        for name, layout in layouts.items()
        for split, m in layout["splits"].items()
        if m["cv_null"] is not None and (m["p_value"] is None or m["p_value"] >= ALPHA)
    ]
    return [
        "CVs indistinguishable from their noise floor (p ≥ 0.05): "
        + (", ".join(floor_only) if floor_only else "none")
        + ".",
        "",
    ]


def _average(layout: dict, splits: list[str], key: str) -> float | None:
    values = [layout["splits"][s][key] for s in splits if s in layout["splits"]]
    return float(np.mean(values)) if values and None not in values else None


def _privileged_note(layouts: dict[str, dict]) -> list[str]:
    marked = [name for name in layouts if policy_label(name) != name]
    return (
        [
            f"{', '.join(marked)}: the privileged scripted expert; it reads the simulator state (object and box "
            "poses), which no real policy sees: a ceiling, not a policy to compare with.",
            "",
        ]
        if marked
        else []
    )


def _summary(layouts: dict[str, dict]) -> list[str]:
    """Is each policy biased? Per policy its averages and the splits with a bias, with none detected, and
    those the test could not judge (and why): a policy that fails everything is not reported unbiased."""
    table = summary_table(layouts)
    return ["## Summary", "", *to_markdown(table), table.legend(), "", *_privileged_note(layouts)]


def _table1(metrics: dict[str, Any], layouts: dict[str, dict]) -> list[str]:
    """Table 1, one per task (the pick_place table keeps the paper's title)."""
    all_splits = split_order(layouts, "splits")
    tasks = list(dict.fromkeys(split_task(s)[0] for s in all_splits))
    lines: list[str] = []
    for task in tasks:
        splits = [s for s in all_splits if split_task(s)[0] == task]
        splits = sorted(
            splits, key=lambda s: (visual_factors() + (split_task(s)[1],)).index(split_task(s)[1])
        )
        lines += _task_table1(metrics, layouts, splits, task if len(tasks) > 1 else None)
    return lines


def _task_table1(
    metrics: dict[str, Any], layouts: dict[str, dict], splits: list[str], task: str | None
) -> list[str]:
    """A row per split and policy: the columns of each split's block on the page (roboview.eval.reporting.tables)."""
    groups = [(split_title(split_task(s)[1]), split_table(metrics, layouts, s)) for s in splits]
    table = Table((POLICY, *SPLIT_COLUMNS)).stacked("Split", groups)
    averages = []
    if task is not None:  # the policy's own averages are the summary's; here those of this task's splits
        averages = [
            "Averages over these splits (SR / CV / cv_excess ×100): "
            + "; ".join(
                f"{name} " + " / ".join(pct(_average(layout, splits, k)) for k in ("sr", "cv", "cv_excess"))
                for name, layout in layouts.items()
            )
            + ".",
            "",
        ]
    title = "## Table 1 — success rate and Bias Coefficient (×100)" + (f", task `{task}`" if task else "")
    return [
        title,
        "",
        *to_markdown(table),
        Table(SPLIT_COLUMNS).legend(),
        "SR is weighted by episodes, not averaged over instances as in the paper. No interval is given "
        "for CV or cv_excess: none has passed the coverage simulation.",
        "",
        *averages,
        *_noise_floor_line(layouts),
    ]


def _table2(layouts: dict[str, dict]) -> list[str]:
    lines: list[str] = []
    for split in split_order(layouts, "interactions"):
        have = {n: lay["interactions"][split] for n, lay in layouts.items() if split in lay["interactions"]}
        a, b = next(iter(have.values()))["factors"]
        header = [
            "Policy",
            "SR",
            f"CV({a})",
            f"p({a})",
            f"CV({b})",
            f"p({b})",
            f"IEC({a}; {b})",
            f"IEC({a}; {b}) null",
            f"IEC({b}; {a})",
            f"IEC({b}; {a}) null",
            "p_interaction",
        ]
        rows, notes = [], []
        for name, m in have.items():
            ab, ba = f"{a}|{b}", f"{b}|{a}"
            rows.append(
                [
                    name,
                    pct(m["sr"]) + pct_ci(m["sr_ci95"]),
                    pct(m["cv"][a]),
                    p_fmt(m["p_value"][a]),
                    pct(m["cv"][b]),
                    p_fmt(m["p_value"][b]),
                    pct(m["iec"][ab]),
                    pct(m["iec_null"][ab]),
                    pct(m["iec"][ba]),
                    pct(m["iec_null"][ba]),
                    p_fmt(m["p_interaction"]),
                ]
            )
            notes.append(f"- {name}: {_interaction_verdict(m, a, b)}")
        lines += [
            f"## Table 2 — {split}: Bias Coefficient and Interaction Effect Coefficient (×100)",
            "",
            *markdown_table(header, rows),
            f"IEC({a}; {b}): how much the bias from {a} changes with {b}. Its null is the IEC of tables "
            "drawn from the fitted additive (no-interaction) binomial GLM: main effects and noise alone "
            "produce it. p_interaction: likelihood-ratio test of A×B against A + B.",
            "",
            *notes,
            "",
        ]
    return lines


def _interaction_verdict(m: dict[str, Any], a: str, b: str) -> str:
    """Say 'interaction' / 'asymmetric coupling' only when it survives calibration."""
    p = m["p_interaction"]
    if p is None:
        return "no informative cells: interaction not testable."
    if p >= ALPHA:
        return (
            f"no evidence of interaction (p_interaction = {p_fmt(p)}); the IECs are what additive effects "
            "and noise produce, so no asymmetry is claimed."
        )
    beyond = [f"IEC({x}; {y})" for x, y in ((a, b), (b, a)) if (m["p_iec"][f"{x}|{y}"] or 1.0) < ALPHA]
    if len(beyond) == 1:
        return f"interaction (p_interaction = {p_fmt(p)}); asymmetric: only {beyond[0]} exceeds its additive null."
    return f"interaction (p_interaction = {p_fmt(p)}); " + (
        "both IECs exceed their additive nulls." if beyond else "neither IEC alone exceeds its additive null."
    )


def _directions(layouts: dict[str, dict]) -> list[str]:
    lines = [
        "## Which values differ (CMH odds ratio vs the other values, stratified by context and repeat; "
        "BH q < 0.05)",
        "",
    ]
    for name, layout in layouts.items():
        for split, m in layout["splits"].items():
            low, high = directions(m)

            def text(items, m=m):
                return (
                    ", ".join(f"{v} (OR {o:.2g}, SR {pct(m['per_value'][v]['sr'])})" for v, o in items)
                    or "none"
                )

            lines.append(f"- {name}, {split}: below the rest: {text(low)}; above the rest: {text(high)}")
    return [*lines, ""]


def _comparisons(metrics: dict[str, Any]) -> list[str]:
    comps = metrics.get("comparisons", [])
    if not comps:
        return []
    rows = [
        [
            c["split"],
            f"{c['policies'][1]} − {c['policies'][0]}",
            str(c["n_pairs"]),
            pct(c["delta_sr"]),
            p_fmt(c["p_sr"]),
            pct(c["delta_cv_excess"]),
            p_fmt(c["p_cv_excess"]),
        ]
        for c in comps
    ]
    return [
        "## Policy comparisons (paired within instance and repeat: same seeds)",
        "",
        *markdown_table(
            [
                "Split",
                "Difference",
                "Pairs",
                "ΔSR ×100",
                "p (McNemar)",
                "Δcv_excess ×100",
                "p (paired permutation)",
            ],
            rows,
        ),
        "",
    ]


def _rankings(metrics: dict[str, Any]) -> list[str]:
    """Per split and overall: policies best first with their significance groups and possible ranks."""
    ranked = metrics.get("rankings")
    if not ranked:
        return []
    lines = [
        "## Rankings",
        "",
        "Best first. Policies sharing a letter are not significantly different (paired tests, Holm-adjusted "
        f"over the pairs, α = {ranked['alpha']}); ranks: the range the tests leave possible.",
        "",
    ]
    rows = []
    for split, entry in [*ranked["splits"].items(), ("overall", ranked["overall"])]:
        for metric, table in entry.items():
            label = {
                "sr": "SR",
                "cv_excess": "cv_excess",
                "cv_excess_mean": "mean cv_excess (no overall test)",
            }[metric]
            rows.append(
                [
                    split,
                    label,
                    ", ".join(
                        f"{r['policy']} {pct(r['value'])} ({r['group']}; {r['rank_range'][0]}"
                        + (f"–{r['rank_range'][1]}" if r["rank_range"][1] != r["rank_range"][0] else "")
                        + ")"
                        for r in table
                    ),
                ]
            )
    return [
        *lines,
        *markdown_table(["Split", "By", "Policies (value ×100, group, possible ranks)"], rows),
        "",
    ]


def _context_factors(layouts: dict[str, dict]) -> list[str]:
    """SR per instruction (and shape, initial position) over that factor's own context subspace."""
    found = {name: layout.get("context_factors") or {} for name, layout in layouts.items()}
    if not any(found.values()):
        return []
    lines = [
        "## Success by task context (SR ×100 per value over the factor's own contexts, every visual "
        "condition; p: GLM likelihood-ratio test of factor + condition against condition)",
        "",
    ]
    rows = []
    for name, factors in found.items():
        for factor, m in factors.items():
            values = "; ".join(
                f"{value}: {pct(v['sr'])} (n={v['n_episodes']})" for value, v in m["per_value"].items()
            )
            rows.append([name, factor, values, p_fmt(m["p_value"]), m["p_value_method"] or "—"])
    lines += markdown_table(["policy", "context factor", "SR by value", "p", "p method"], rows)
    lines += [
        "",
        "A policy that ignores language (ACT) should show no instruction effect; a language-conditioned one "
        "(SmolVLA, π0) that does is sensitive to the wording of one goal.",
        "",
    ]
    return lines


def _diagnostics(layouts: dict[str, dict]) -> list[str]:
    rows = []
    for name, layout in layouts.items():
        for split, m in layout["splits"].items():
            rows.append(
                [
                    name,
                    split,
                    str(m["n_instances"]),
                    str(m["n_episodes"]),
                    str(m["n_contexts"]),
                    str(m["n_contexts_all_failed"]),
                    m["p_value_method"] or "—",
                    p_fmt(m["p_value_cv"], m.get("p_value_cv_at_floor"))
                    + (f" ({m['p_value_cv_draws']} draws)" if m.get("p_value_cv_draws") else ""),
                ]
            )
    control = [
        f"- {name}: baseline instance agrees across splits in {pct(c['agreement'])} % of {c['n_pairs']} "
        f"(context, repeat) pairs; baseline SR by split: "
        + ", ".join(f"{s} {pct(v)}" for s, v in c["sr_by_split"].items())
        for name, layout in layouts.items()
        if (c := layout.get("control"))
    ]
    return [
        "## Sample sizes, calibration and the control arm",
        "",
        *markdown_table(
            [
                "Policy",
                "Split",
                "Instances",
                "Episodes",
                "Contexts",
                "Contexts all failed",
                "p calibration",
                "p (CV permutation)",
            ],
            rows,
        ),
        "Control arm (test–retest): the all-baseline instance of each context runs, with the same seeds, in "
        "the color, camera_euler and dist_scale splits.",
        *control,
        "",
    ]


def _adaptive(layouts: dict[str, dict]) -> list[str]:
    """Splits evaluated adaptively: rounds, episodes and why each stopped."""
    rows = [
        [
            name,
            split,
            str(a["rounds"]),
            str(a["episodes"]),
            a["stopped"],
            "—" if a["lrt"] is None else f"{a['lrt']:.2f}",
            "—" if a["efficacy_boundary"] is None else f"{a['efficacy_boundary']:.2f}",
            "—" if a["futility_boundary"] is None else f"{a['futility_boundary']:.2f}",
        ]
        for name, layout in layouts.items()
        for split, m in layout["splits"].items()
        if (a := m.get("adaptive"))
    ]
    if not rows:
        return []
    design = next(
        m["adaptive"]["design"]
        for layout in layouts.values()
        for m in layout["splits"].values()
        if m.get("adaptive")
    )
    return [
        "## Adaptive sampling",
        "",
        f"Repeats ran in rounds; from round {design['min_rounds']} on, after each round, a group-sequential LRT decided "
        f"(α = {design['alpha']} over every look, futility against a bias of logit SD τ = {design['tau']} at power "
        f"{design['power']}, at most {design['max_repeats']} rounds; docs/adaptive.md). The sampling was adaptive: "
        "the fixed-sample statistics in the tables above treat the episodes run as a fixed sample, and their "
        "p-values are approximate; the stop below is the sequential test's decision.",
        "",
        *markdown_table(
            ["Policy", "Split", "Rounds", "Episodes", "Stopped", "LRT", "efficacy bound", "futility bound"],
            rows,
        ),
        "",
    ]


def _isolation(layouts: dict[str, dict]) -> list[str]:
    """Per split: how many (context, repeat) blocks were verified to differ only in the factor (eval/running/isolation.py)."""
    rows, violations = [], []
    for name, layout in layouts.items():
        for split, m in {**layout["splits"], **layout.get("interactions", {})}.items():
            cert = m.get("isolation")
            if cert is None:
                continue
            if not cert["recorded"]:
                rows.append([name, split, str(cert["blocks"]), "not recorded", "—"])
                continue
            bad = cert["violations"]
            rows.append(
                [
                    name,
                    split,
                    str(cert["blocks"]),
                    f"{cert['verified']} / {cert['blocks']}",
                    "none" if not bad else f"{len(bad)} (left out of the tests)",
                ]
            )
            violations += [
                f"- {name}, {split}: context {v['context_id']} repeat {v['repeat']} — "
                f"{', '.join(v['components'])} differ across {', '.join(v['values'][:6])}"
                f"{' …' if len(v['values']) > 6 else ''}"
                for v in bad[:20]
            ]
    if not rows:
        return []
    return [
        "## Isolation certificate",
        "",
        "Every value of one (context, repeat) must share the instruction, the initial robot state and object pose, "
        "the episode seed, every other factor's value and the calibration of the cameras the factor does not move.",
        "",
        *markdown_table(["Policy", "Split", "Blocks", "Verified identical", "Violations"], rows),
        *violations,
        "",
    ]


def _infra_errors(layouts: dict[str, dict]) -> list[str]:
    """Per split: the episodes infrastructure ended, left out of every number (`n_infra_errors`)."""
    lines = []
    for name, layout in layouts.items():
        listed = 0
        for split, m in {**layout["splits"], **layout.get("interactions", {})}.items():
            if m.get("n_infra_errors"):
                listed += m["n_infra_errors"]
                lines.append(
                    f"- {name}, {split}: {m['n_infra_errors']} episode(s) ended by infrastructure, not counted"
                )
        if layout.get("n_infra_errors", 0) > listed:
            lines.append(
                f"- {name}: {layout['n_infra_errors'] - listed} more episode(s) ended by infrastructure, not "
                "counted, in splits where no episode counts"
            )
    if not lines:
        return []
    return [
        "## Episodes ended by infrastructure",
        "",
        "Episodes ended by infrastructure, not by the policy (a policy server lost mid-episode, an endpoint still "
        "failing after its retries, a worker that died, a render failure; `status` infra_error, the reason in "
        "`failure_reason`) are left out of every rate and test. Rerunning the evaluation command into the same "
        "output folder runs them again.",
        "",
        *lines,
        "",
    ]


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


def _videos(metrics: dict[str, Any], layouts: dict[str, dict]) -> list[str]:
    """Per-value table of the episodes filmed (--eval.videos), each video linked: the page's video tables."""
    groups = [(split, videos_table(metrics, layouts, split)) for split in video_splits(metrics)]
    if not groups:
        return []
    return [
        "## Episode videos (per value; `--eval.videos`)",
        "",
        *to_markdown(Table(VIDEO_COLUMNS).stacked("Split", groups)),
    ]


def _stacks(sources: list[dict[str, Any]]) -> list[str]:
    """Per results file: the conformance verdict of each run with its measured drift and stack; then what differs
    between the stacks the files ran on (their numbers compare only as far as their stacks do)."""
    from roboview.sim import stack

    lines, seen = ["## Simulation stack and conformance", ""], []
    for source in sources:
        for entry in source.get("provenance") or []:
            conf = entry.get("conformance")
            if not conf:
                lines.append(f"- `{source['path']}` ({entry['started']}): no conformance check recorded")
                continue
            d = conf["drift"]
            lines.append(
                f"- `{source['path']}` ({entry['started']}): **{conf['verdict']}** on "
                f"{stack.summary(conf.get('stack'))}; {d['images_identical']}/{d['images']} reference images "
                f"and {d['physics_identical']}/{d['physics']} rollouts bit-identical, at most "
                f"{d['pixel_fraction_max']:.3%} of an image's pixels differ, joints within {d['joint_max']:.1e} rad"
            )
            if conf.get("stack_differences"):
                lines.append(
                    f"  - differs from the stack that built the benchmark: {'; '.join(conf['stack_differences'])}"
                )
            seen.append((source["path"], conf.get("stack"), conf["verdict"]))
    for path, other, verdict in seen[1:]:
        differences = stack.differences(seen[0][1], other)
        if differences or verdict != seen[0][2]:
            lines.append(
                f"- **The runs differ**: `{seen[0][0]}` ({seen[0][2]}) vs `{path}` ({verdict}): "
                f"{'; '.join(differences) or 'same stack'}"
            )
    return lines + [""] if len(lines) > 2 else []


def provenance_section(sources: list[dict[str, Any]]) -> list[str]:
    """What produced each results file: versions, checkpoint hash, command, machine, times."""
    lines = ["## Provenance", ""]
    for source in sources:
        for entry in source.get("provenance") or []:
            ckpt = entry.get("checkpoint") or {}
            packages = ", ".join(f"{k} {v}" for k, v in entry["packages"].items() if v)
            machine = entry["machine"]
            lines += [
                f"- `{source['path']}`: {entry['started']} → {entry.get('ended') or 'interrupted'}, "
                f"{entry.get('episodes_run', '?')} episodes; roboview commit {entry.get('roboview_commit') or '—'}",
                f"  - command: `{entry['command']}`",
                f"  - packages: {packages}",
                f"  - benchmark {entry['benchmark_version']}; checkpoint "
                f"{(ckpt.get('path', '') + ' sha256 ' + ckpt.get('sha256', '')[:16] + '…') if ckpt else '—'}",
                f"  - machine: {machine['cpu']} × {machine['cpu_count']}, GPU {machine.get('gpu') or 'none'}; "
                f"seeds: {entry['seed_rule']}",
            ]
            if entry.get("policy_server"):
                lines.append(
                    f"  - policy served elsewhere (its randomness is the server's, not the episode seeds'): "
                    f"{_served(entry['policy_server'])}"
                )
    return lines + [""] if len(lines) > 2 else []


def _served(server: dict) -> str:
    """One line for a served policy's provenance: protocol, where, and what the server said about itself."""
    where = server.get("urls") or server.get("servers") or server.get("server") or "?"
    where = ", ".join(where) if isinstance(where, list) else str(where)
    said = {
        url: meta.get("roboview", meta) if isinstance(meta, dict) else meta
        for url, meta in (server.get("metadata") or {}).items()
    }
    return f"{server.get('protocol', '?')} at {where}" + (
        f"; server metadata {json.dumps(said)}" if said else ""
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


def markdown_sections(metrics: dict[str, Any]) -> dict[str, list[str]]:
    """report.md's sections in order, each a list of Markdown lines (empty when it has nothing to say)."""
    layouts = policy_layouts(metrics)
    return {
        "summary": _summary(layouts),
        "table1": _table1(metrics, layouts),
        "infra": _infra_errors(layouts),
        "directions": _directions(layouts),
        "interactions": _table2(layouts),
        "comparisons": _comparisons(metrics),
        "rankings": _rankings(metrics),
        "context": _context_factors(layouts),
        "adaptive": _adaptive(layouts),
        "diagnostics": _diagnostics(layouts),
        "isolation": _isolation(layouts),
        "extremes": _extremes(layouts),
        "videos": _videos(metrics, layouts),
        "agents": agents_markdown(metrics.get("agents", {})),
        "stack": _stacks(metrics.get("sources", [])),
        "provenance": provenance_section(metrics.get("sources", [])),
    }


def render_markdown(
    metrics: dict[str, Any], plots: dict[str, str | None], sections: dict[str, list[str]] | None = None
) -> str:
    """report.md from a metrics dict (every number printed is read from it), plot outcomes and, when already
    built, its `markdown_sections`."""
    layouts = policy_layouts(metrics)
    settings = metrics["resampling"]
    lines = [
        "# RoboView-Bias report",
        "",
        f"Policies: {', '.join(layouts)}. ε = {metrics['epsilon']:g}; {resampling_line(settings)}.",
        "",
    ]
    for source in metrics.get("sources", []):
        lines.append(
            f"- source `{source['path']}` (benchmark version {source[VERSION_KEY] or 'not recorded'})"
        )
    lines.append("")
    for section in (sections if sections is not None else markdown_sections(metrics)).values():
        lines += section
    lines += ["## Plots", ""]
    for name, reason in plots.items():
        lines.append(f"![{name}]({name})" if reason is None else f"- {name} skipped: {reason}")
    return "\n".join(lines) + "\n"


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
        for source in sources:  # adaptive runs: when and why each split stopped
            if source.get("adaptive") and len(source.get("policies", [])) == 1:
                layout = policy_layouts(metrics).get(source["policies"][0], {})
                for split, record in source["adaptive"]["splits"].items():
                    if split in layout.get("splits", {}):
                        layout["splits"][split]["adaptive"] = record | {
                            "design": source["adaptive"]["design"]
                        }
    episodes = counted(episodes)  # what infrastructure ended is in no number (metrics counted it)
    for name, layout in policy_layouts(metrics).items():  # success by instruction, shape, initial position
        layout["context_factors"] = context_breakdown(episodes[episodes["policy"] == name], cfg)
    agents = describe_agents(episodes)
    if agents:
        metrics["agents"] = agents
    videos = video_index(episodes, out.resolve())
    if videos:
        metrics["videos"] = videos
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
