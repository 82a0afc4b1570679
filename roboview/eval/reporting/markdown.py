"""report.md: the report in Markdown, every number read from a metrics dict (`compute_all_metrics` plus what
`write_report` adds), so report.md and metrics.json cannot disagree.

The sections on what the results say are here: the summary, Table 1 (one per task), which values differ,
Table 2 (the interactions), the policy comparisons and rankings, success by task context, the values furthest
from their context mean, the filmed episodes. Those on how the results were obtained are in
roboview.eval.reporting.run_sections; `markdown_sections` puts them all in order, and report.html renders the
same sections. SR, CV, cv_excess and IEC are printed ×100 as in the paper's Tables 1 and 2, p-values as they are.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from roboview.eval.reporting import decomposition, run_sections
from roboview.eval.reporting.format import (
    ALPHA,
    against_control,
    directions,
    p_fmt,
    pct,
    pct_ci,
    policy_label,
    resampling_line,
    split_order,
    split_title,
)
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
from roboview.eval.running.agents import agents_markdown
from roboview.eval.running.results import VERSION_KEY
from roboview.eval.statistics.metrics import policy_layouts
from roboview.variation.factors import visual_factors
from roboview.variation.instances import split_task

_N_EXTREMES = 3  # values listed at each end of the per-value deviation ranking


def markdown_sections(metrics: dict[str, Any]) -> dict[str, list[str]]:
    """report.md's sections in order, each a list of Markdown lines (empty when it has nothing to say)."""
    layouts = policy_layouts(metrics)
    return {
        "summary": _summary(layouts),
        "table1": _table1(metrics, layouts),
        "infra": run_sections.infra_section(layouts),
        "copies": run_sections.copies_section(layouts),
        "directions": _directions(layouts),
        "interactions": _table2(layouts),
        "analyses": _analyses(layouts),
        "strips": _strips(metrics.get("strips")),
        "comparisons": _comparisons(metrics),
        "rankings": _rankings(metrics),
        "context": _context_factors(layouts),
        "adaptive": run_sections.adaptive_section(layouts),
        "diagnostics": run_sections.diagnostics_section(layouts),
        "isolation": run_sections.isolation_section(layouts),
        "extremes": _extremes(layouts),
        "videos": _videos(metrics, layouts),
        "agents": agents_markdown(metrics.get("agents", {})),
        "stack": run_sections.stack_section(metrics.get("sources", [])),
        "provenance": run_sections.provenance_section(metrics.get("sources", [])),
    }


def _strips(strips: dict[str, Any] | None) -> list[str]:
    """The discordant pairs of each value that differs from its control arm, replayed and drawn (metrics.json
    `strips`, written by roboview-report)."""
    if not strips or not (strips["drawn"] or strips["skipped"]):
        return []
    lines = [
        "## Where they part",
        "",
        "For each value that differs from its control arm (McNemar p < 0.05), its strongest discordant pair replayed "
        "with the recorded policy: the policy's camera at the first step, where the two episodes' actions part, and "
        "at the end; the control arm above, the value below.",
        "",
    ]
    for s in strips["drawn"]:
        parting = "never part" if s["parting"] is None else f"part at step {s['parting']}"
        faithful = (
            ""
            if s["faithful"]
            else " The replay did not reproduce its recorded rows: it shows a replay here."
        )
        lines += [
            f"**{s['policy']}, {s['split']} = {s['value']}** against {s['against']}: episode {s['instance_id']} "
            f"repeat {s['repeat']}, camera {s['camera']}; their actions {parting}.{faithful}",
            "",
            f"![{s['split']} = {s['value']} against {s['against']}]({s['file']})",
            "",
            f"Replay it side by side in Rerun: `{s['command']}`",
            "",
        ]
    lines += [f"- not drawn: {reason}" for reason in strips["skipped"]]
    return lines + [""]


def _analyses(layouts: dict[str, dict]) -> list[str]:
    """Each task analysis (metrics.json `analyses`, `Task.analyses`) in its own words, per policy."""
    from roboview.tasks.base import analysis_designs

    lines: list[str] = []
    for key, design in analysis_designs().items():
        ran = {
            name: layout["analyses"][key]
            for name, layout in layouts.items()
            if key in layout.get("analyses", {})
        }
        if ran:
            lines += [f"## {design.title}", ""]
            for name, result in ran.items():
                lines += decomposition.markdown(result, name, design)
    return lines


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
        "SR is weighted by episodes, not averaged over instances as in the paper. cv_excess's interval is a "
        "parametric bootstrap whose coverage was checked by simulation (docs/statistics.md); CV has none.",
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

            lines.append(
                f"- {name}, {split}: below the rest: {text(low)}; above the rest: {text(high)}"
                + against_control(m)
            )
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
