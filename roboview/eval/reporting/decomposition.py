"""A factor decomposition in the report (roboview.eval.statistics.decompose; the design a task declares,
`Task.analyses`): report.md's lines for one policy's result, in the design's words, and the dose–response figure.
Rates and points are printed as every other section prints them (`roboview.eval.reporting.format`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from roboview.eval.reporting.format import p_fmt, pct, pct_ci
from roboview.eval.reporting.tables import markdown_table
from roboview.tasks.decomposition import Decomposition
from roboview.variation.factors import FACTORS


def ci_cell(ci: list[float] | None) -> str:
    """A rate's or a difference's 95 % interval ×100 as a table cell ("N/A" where there is none)."""
    return pct_ci(ci).strip() or "N/A"


def points(x: float | None) -> str:
    """A difference of rates in points, signed ("+3.25", "N/A")."""
    return "N/A" if x is None else f"{100 * x:+.2f}"


def markdown(result: dict[str, Any], policy: str, design: Decomposition) -> list[str]:
    """report.md's lines for one policy's decomposition."""
    return [
        f"### {policy}",
        "",
        totals_line(result, design),
        "",
        *twin_lines(result, design),
        *kinds_lines(result),
        *interaction_lines(result),
        *dose_lines(result),
        *variant_lines(result, design),
    ]


def _told(result: dict[str, Any], design: Decomposition) -> str:
    """The sentence on the instruction: the words of the first declared value that ran (the last's where none did)."""
    if not design.instructions:
        return ""
    ran = set(result["instruction"])
    words = next((w for value, w in design.instructions if value in ran), design.instructions[-1][1])
    return f" Instruction: {words}."


def totals_line(result: dict[str, Any], design: Decomposition) -> str:
    """The factor's number both ways, over every variant run and over the fair ones, and the no-change view's."""
    total = result[design.name]
    (micro, micro_words), (macro, macro_words) = design.micro, design.macro
    lp, base = total[micro], total["no_change"]
    groups = ", ".join(f"{g} {pct(r['sr'])} (n {r['n']})" for g, r in total["per_suite"].items())
    fair = total.get("fair")
    over_fair = (
        f" Over the {fair['n_variants']:,} variants the fairness gate passes ({total['n_variants_unfair']:,} of "
        f"{design.source}'s set it does not: the target leaves the frame or hides, kept as {design.source} runs "
        f"them): **{pct(fair[micro]['sr'])}**{pct_ci(fair[micro]['ci95'])} {micro_words}, {pct(fair[macro])} "
        f"{macro_words}."
        if fair
        else ""
    )
    return (
        f"{design.name.capitalize()} success rate over {design.source}'s {total['n_variants']:,} variants run: "
        f"**{pct(lp['sr'])}**{pct_ci(lp['ci95'])} {micro_words} ({lp['n']:,} episodes alike); {pct(total[macro])} "
        f"{macro_words} (the {design.groups_word}' mean: {groups}).{over_fair} The no-change view: "
        f"{pct(base['sr'])}{pct_ci(base['ci95'])} (n {base['n']}).{_told(result, design)}"
    )


def twin_lines(result: dict[str, Any], design: Decomposition) -> list[str]:
    """The factor's number over the twins beside the external one, and each kind's twins against their originals."""
    twin = result.get("twin")
    if not twin or design.twin is None:
        return []
    (micro, micro_words), (macro, macro_words) = design.micro, design.macro
    lines = []
    against = twin["against_original"]
    if against is not None:
        lines += [
            f"{design.name.capitalize()} success rate {design.twin.name}, {design.twin.words}, over the twins of "
            f"{design.source}'s {twin['n_variants']:,} variants: **{pct(twin[micro]['sr'])}**"
            f"{pct_ci(twin[micro]['ci95'])} {micro_words}, {pct(twin[macro])} {macro_words}; against the same "
            f"variants as {design.source} runs them ({pct(against['sr_original'])}): "
            f"{points(against['difference'])} points{pct_ci(against['ci95'])}, p {p_fmt(against['p'])} over "
            f"{against['n_blocks']} blocks.",
            "",
        ]
    rows = [
        [
            name,
            str(k["n_variants"]),
            pct(k["sr_original"]),
            pct(k["sr"]),
            points(k["difference"]),
            ci_cell(k["ci95"]),
            p_fmt(k["p"]),
            str(k["n_blocks"]),
        ]
        for name, k in twin["kinds"].items()
    ]
    return lines + [
        f"Each kind {design.twin.name} against the same variants without it (each severity run), paired by block; "
        "difference in points, 95 % bootstrap interval over blocks, sign-flip p over blocks:",
        "",
        *markdown_table(
            [
                "Change",
                "Variants",
                "SR without",
                f"SR {design.twin.name}",
                "Difference",
                "95 % CI",
                "p",
                "Blocks",
            ],
            rows,
        ),
        "",
    ]


def kinds_lines(result: dict[str, Any]) -> list[str]:
    rows = [
        [
            name,
            str(k["n_variants"]),
            pct(k["sr"]),
            points(k["effect"]),
            ci_cell(k["ci95_effect"]),
            p_fmt(k["p"]),
            str(k["n_blocks"]),
        ]
        for name, k in result["kinds"].items()
    ]
    if not rows:
        return []
    return [
        "Each kind of change against the no-change view, paired by block (context, repeat, seed); effect in "
        "points, 95 % bootstrap interval over blocks, sign-flip p over blocks:",
        "",
        *markdown_table(["Change", "Variants", "SR", "Effect", "95 % CI", "p", "Blocks"], rows),
        "",
    ]


def interaction_lines(result: dict[str, Any]) -> list[str]:
    rows = [
        [name, str(i["n_variants"]), points(i["interaction"]), ci_cell(i["ci95"]), p_fmt(i["p"])]
        for name, i in result["interactions"].items()
        if i["n_variants"]
    ]
    if not rows:
        return []
    return [
        "Interaction, S(both) − S(first) − S(second) + S(none): negative when the two changes together cost "
        "more than each alone adds up to:",
        "",
        *markdown_table(["Two changes", "Variants with both parts", "Interaction", "95 % CI", "p"], rows),
        "",
    ]


def dose_lines(result: dict[str, Any]) -> list[str]:
    lines = []
    for name, d in result["dose_response"].items():
        half, ci = d["half_magnitude"], d["half_magnitude_ci95"]
        said = (
            f"success falls to half its fitted no-change level ({pct(d['sr_at_0'])}) at {half:.1f} {d['unit']}"
            + ("" if ci is None else f" [{ci[0]:.1f}, {ci[1]:.1f}]")
            if half is not None
            else "no decline to half of the no-change level could be fitted"
            + ("" if d["slope"] is None else f" (slope {d['slope']:+.3f} per unit)")
        )
        curve = "; ".join(f"{c['magnitude']:g}: {pct(c['sr'])} (n {c['n']})" for c in d["curve"][:12])
        lines += [
            f"Dose–response over {name} ({d['n']} episodes): {said}. Success by magnitude: {curve}.",
            "",
        ]
    return lines


def variant_lines(result: dict[str, Any], design: Decomposition) -> list[str]:
    worst = sorted(
        (v for v in result["per_variant"] if v["delta_control"] is not None),
        key=lambda v: v["delta_control"],
    )[:10]
    if not worst:
        return []
    rows = [
        [
            v["task"],
            v["value"],
            v["kind"],
            pct(v["sr"]),
            ci_cell(v["ci95"]),
            points(v["delta_control"]),
            ci_cell(v.get("delta_control_ci95")),
            p_fmt(v["p_control"]),
        ]
        for v in worst
    ]
    factor = FACTORS.get(design.group_column)
    return [
        "Per variant over its repeats (the ten that cost most against the no-change view; Δ ×100 with its paired "
        "95 % interval, McNemar's p):",
        "",
        *markdown_table(
            [
                factor.title if factor else design.group_column,
                "View",
                "Change",
                "SR",
                "95 % CI",
                "Δ",
                "Δ 95 % CI",
                "p",
            ],
            rows,
        ),
        "",
    ]


def plot(results: dict[str, dict[str, Any]], output_dir, design: Decomposition) -> dict[str, str | None]:
    """Success against each dose factor's severity, per policy: the rates with Clopper–Pearson intervals, the fitted
    logistic curve, and the half-severity with its interval (a shaded band)."""
    import matplotlib.pyplot as plt

    factors = [f for f in design.dose_factors if any(f.name in r["dose_response"] for r in results.values())]
    if not factors:
        names = " or ".join(f.name for f in design.dose_factors)
        return {design.figure: f"no single-change {names} views ran"}
    fig, axes = plt.subplots(
        1, len(factors), figsize=(5.5 * len(factors), 4), layout="constrained", squeeze=False
    )
    for ax, factor in zip(axes[0], factors):
        for i, (policy, result) in enumerate(results.items()):
            d = result["dose_response"].get(factor.name)
            if d is not None:
                _panel(ax, d, policy, f"C{i}")
        ax.set(
            xlabel=factor.axis or factor.name,
            ylabel="success rate",
            ylim=(-0.05, 1.05),
            title=f"Success vs {factor.name} ({design.source} views)",
        )
        ax.legend(fontsize=8)
    fig.savefig(Path(output_dir) / design.figure, dpi=110)
    plt.close(fig)
    return {design.figure: None}


def _panel(ax, d: dict[str, Any], policy: str, color: str) -> None:
    x = np.array([c["magnitude"] for c in d["curve"]])
    sr = np.array([c["sr"] for c in d["curve"]])
    lo = np.array([c["ci95"][0] for c in d["curve"]])
    hi = np.array([c["ci95"][1] for c in d["curve"]])
    err = np.clip([sr - lo, hi - sr], 0, None)  # the ends hold the rate; the clip absorbs float noise
    ax.errorbar(x, sr, yerr=err, fmt="o", ms=3, capsize=2, color=color, label=policy)
    if d["slope"] is not None:
        a = np.log(d["sr_at_0"] / (1 - d["sr_at_0"]))
        grid = np.linspace(0, x.max(), 100)
        ax.plot(grid, 1 / (1 + np.exp(-(a + d["slope"] * grid))), color=color, lw=1)
    if d["half_magnitude"] is not None:
        ax.axvline(d["half_magnitude"], color=color, ls="--", lw=1)
        if d["half_magnitude_ci95"] is not None:
            ax.axvspan(*d["half_magnitude_ci95"], color=color, alpha=0.12)
