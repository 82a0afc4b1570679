"""The report half of LIBERO-plus's camera decomposition (roboview.libero.decomposition, whose `markdown`, `plot` and
`FIGURE` these are): report.md's lines for one policy's analysis and the dose-response figure."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f}"


def _ci(ci: list[float] | None, scale: float = 100) -> str:
    return "—" if ci is None else f"[{scale * ci[0]:.1f}, {scale * ci[1]:.1f}]"


def _p(p: float | None) -> str:
    return "—" if p is None else (f"{p:.2g}" if p >= 0.001 else "< 0.001")


def markdown(
    result: dict[str, Any], policy: str, table: Callable[[list[str], list[list[str]]], list[str]]
) -> list[str]:
    """report.md's lines for one policy's analysis; `table(headers, rows)` writes a Markdown table (the report's)."""
    return [
        f"### {policy}",
        "",
        camera_line(result),
        "",
        *_kinds_lines(result, table),
        *_interaction_lines(result, table),
        *_dose_lines(result),
        *_variant_lines(result, table),
    ]


def camera_line(result: dict[str, Any]) -> str:
    cam = result["camera"]
    lp, base = cam["liberoplus"], cam["no_change"]
    suites = ", ".join(f"{s} {_pct(r['sr'])} (n {r['n']})" for s, r in cam["per_suite"].items())
    told = (
        "LIBERO-plus's own (it names the view: every value also changes the instruction)"
        if "liberoplus" in result["instruction"]
        else "LIBERO's own, whatever the view (only the camera changes)"
    )
    fair = cam.get("fair")
    over_fair = (
        f" Over the {fair['n_variants']:,} variants the fairness gate passes ({cam['n_variants_unfair']:,} of LIBERO-"
        f"plus's set it does not: the target leaves the frame or hides, kept as LIBERO-plus runs them): "
        f"**{_pct(fair['liberoplus']['sr'])}** {_ci(fair['liberoplus']['ci95'])} as LIBERO-plus totals it, "
        f"{_pct(fair['vla_eval'])} as vla-eval averages it."
        if fair
        else ""
    )
    return (
        f"Camera success rate over LIBERO-plus's {cam['n_variants']:,} variants run: **{_pct(lp['sr'])}** "
        f"{_ci(lp['ci95'])} as LIBERO-plus totals it ({lp['n']:,} episodes alike); {_pct(cam['vla_eval'])} as "
        f"vla-eval averages it (the suites' mean: {suites}).{over_fair} The no-change view: {_pct(base['sr'])} "
        f"{_ci(base['ci95'])} (n {base['n']}). Instruction: {told}."
    )


def _kinds_lines(result: dict[str, Any], table) -> list[str]:
    rows = [
        [
            name,
            str(k["n_variants"]),
            _pct(k["sr"]),
            "—" if k["effect"] is None else f"{100 * k['effect']:+.1f}",
            _ci(k["ci95_effect"]),
            _p(k["p"]),
            str(k["n_blocks"]),
        ]
        for name, k in result["kinds"].items()
    ]
    if not rows:
        return []
    return [
        "Each kind of change against the no-change view, paired by block (task, init state, seed); effect in "
        "points, 95 % bootstrap interval over blocks, sign-flip p over blocks:",
        "",
        *table(["Change", "Variants", "SR", "Effect", "95 % CI", "p", "Blocks"], rows),
        "",
    ]


def _interaction_lines(result: dict[str, Any], table) -> list[str]:
    rows = [
        [
            name,
            str(i["n_variants"]),
            "—" if i["interaction"] is None else f"{100 * i['interaction']:+.1f}",
            _ci(i["ci95"]),
            _p(i["p"]),
        ]
        for name, i in result["interactions"].items()
        if i["n_variants"]
    ]
    if not rows:
        return []
    return [
        "Interaction, S(both) − S(first) − S(second) + S(none): negative when the two changes together cost "
        "more than each alone adds up to:",
        "",
        *table(["Two changes", "Variants with both parts", "Interaction", "95 % CI", "p"], rows),
        "",
    ]


def _dose_lines(result: dict[str, Any]) -> list[str]:
    lines = []
    for name, d in result["dose_response"].items():
        half = d["half_magnitude"]
        said = (
            f"success falls to half its fitted no-change level ({_pct(d['sr_at_0'])}) at {half:.1f} {d['unit']} "
            f"{_ci(d['half_magnitude_ci95'], 1)}"
            if half is not None
            else "no decline to half of the no-change level could be fitted"
            + ("" if d["slope"] is None else f" (slope {d['slope']:+.3f} per unit)")
        )
        points = "; ".join(f"{c['magnitude']:g}: {_pct(c['sr'])} (n {c['n']})" for c in d["curve"][:12])
        lines += [
            f"Dose–response over {name} ({d['n']} episodes): {said}. Success by magnitude: {points}.",
            "",
        ]
    return lines


def _variant_lines(result: dict[str, Any], table) -> list[str]:
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
            _pct(v["sr"]),
            _ci(v["ci95"]),
            f"{100 * v['delta_control']:+.1f}",
            _p(v["p_control"]),
        ]
        for v in worst
    ]
    return [
        "Per variant over its repeats (the ten that cost most against the no-change view, McNemar's exact p):",
        "",
        *table(["Task", "View", "Change", "SR", "95 % CI", "Δ", "p"], rows),
        "",
    ]


FIGURE = "analysis_liberoplus_dose_response.png"


def plot(results: dict[str, dict[str, Any]], output_dir) -> dict[str, str | None]:
    """Success against azimuth magnitude and against scale, per policy: the rates with Clopper–Pearson intervals, the
    fitted logistic curve, and the half-magnitude with its interval (a shaded band)."""
    from pathlib import Path

    import matplotlib.pyplot as plt

    panels = [
        name for name in ("azimuth", "scale") if any(name in r["dose_response"] for r in results.values())
    ]
    if not panels:
        return {FIGURE: "no single-change azimuth or scale views ran"}
    fig, axes = plt.subplots(
        1, len(panels), figsize=(5.5 * len(panels), 4), layout="constrained", squeeze=False
    )
    for ax, name in zip(axes[0], panels):
        for i, (policy, result) in enumerate(results.items()):
            d = result["dose_response"].get(name)
            if d is None:
                continue
            x = np.array([c["magnitude"] for c in d["curve"]])
            sr = np.array([c["sr"] for c in d["curve"]])
            lo = np.array([c["ci95"][0] for c in d["curve"]])
            hi = np.array([c["ci95"][1] for c in d["curve"]])
            color = f"C{i}"
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
        unit = "|azimuth| (degrees)" if name == "azimuth" else "scale − 100 (percent)"
        ax.set(
            xlabel=unit,
            ylabel="success rate",
            ylim=(-0.05, 1.05),
            title=f"Success vs {name} (LIBERO-plus views)",
        )
        ax.legend(fontsize=8)
    fig.savefig(Path(output_dir) / FIGURE, dpi=110)
    plt.close(fig)
    return {FIGURE: None}
