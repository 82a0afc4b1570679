"""How the reports print numbers and order splits (shared by report.md and report.html)."""

from __future__ import annotations

from collections.abc import Sequence

from roboview.tasks import DEFAULT_TASK
from roboview.variation.factors import FACTORS, visual_factors
from roboview.variation.instances import split_task

ALPHA = 0.05  # level at which the report calls a difference significant


PRIVILEGED_POLICIES = ("expert",)  # policy names (before any "+sgl") of types that read the simulator state


def policy_label(name: str) -> str:
    """A policy's name as the reports list it: the scripted expert is marked privileged."""
    return f"{name} (privileged)" if str(name).partition("+")[0] in PRIVILEGED_POLICIES else str(name)


def pct(x: float | None) -> str:
    """A ratio ×100 with two decimals, the paper's table convention; N/A for null."""
    return "N/A" if x is None else f"{100 * x:.2f}"


def pct_ci(ci: Sequence[float] | None) -> str:
    return "" if ci is None else f" [{pct(ci[0])}, {pct(ci[1])}]"


def p_fmt(p: float | None, at_floor: bool | None = False) -> str:
    """A p-value as printed: 4 decimals, scientific below 1e-4, and "≤ x" where a Monte Carlo floor binds
    (no draw reached the statistic: the true p may be smaller)."""
    if p is None:
        return "N/A"
    text = f"{p:.4f}" if p >= 1e-4 else f"{p:.1e}"
    return f"≤ {text}" if at_floor else text


def resampling_line(settings: dict) -> str:
    """The report's one sentence on its resampling, in docs/statistics.md's words."""
    most = (
        f", up to {settings['max_perm']:,} for a p-value still undecided" if settings.get("max_perm") else ""
    )
    return (
        f"noise floor (cv_null) and the CV permutation test: {settings['n_perm']:,} within-block permutations{most}; "
        f"GLM p-value where cells are sparse: {settings['n_glm']:,} permutation draws; seed {settings['seed']}"
    )


def bias_status(m: dict) -> tuple[str, str]:
    """What a split's test says about its factor: ("bias", ""), ("no bias detected", ""), or ("not testable",
    why) — every episode failed, every episode succeeded, or too few episodes for the test. "No bias detected"
    is said only of a split the test could have flagged."""
    sr, p = m.get("sr"), m.get("p_value")
    if sr == 0:
        return "not testable", "every episode failed"
    if sr == 1:
        return "not testable", "every episode succeeded"
    if p is None:
        return "not testable", "too few episodes for the test"
    return ("bias", "") if p < ALPHA else ("no bias detected", "")


def directions(m: dict) -> tuple[list[tuple[str, float]], list[tuple[str, float]]]:
    """A split's values whose CMH odds ratio against the rest is significant (BH q < ALPHA): those below the
    rest (OR < 1, lowest first) and those above (OR > 1, highest first), each as (value, odds ratio)."""
    sig = [
        (v, s["odds_ratio"])
        for v, s in m["per_value"].items()
        if s["q_value"] is not None and s["q_value"] < ALPHA and s["odds_ratio"] is not None
    ]
    low = sorted(((o, v) for v, o in sig if o < 1))
    high = sorted(((o, v) for v, o in sig if o > 1), reverse=True)
    return [(v, o) for o, v in low], [(v, o) for o, v in high]


def against_control(m: dict) -> str:
    """The clause that names a split's values differing from its control arm on the same (context, repeat) seeds
    (McNemar p < ALPHA), each difference ×100 with its paired 95 % interval (`delta_control_ci95`): "; against the
    control arm (…): blue -50.00 [-75.33, -10.12] (p 0.004)", "…: none" where none does; empty where no control
    episode ran."""
    paired = {v: s for v, s in m["per_value"].items() if s.get("p_control") is not None}
    if not paired:
        return ""
    sig = sorted((s["delta_control"], v) for v, s in paired.items() if s["p_control"] < ALPHA)
    named = (
        ", ".join(
            f"{v} {100 * d:+.2f}{pct_ci(paired[v].get('delta_control_ci95'))} (p {p_fmt(paired[v]['p_control'])})"
            for d, v in sig
        )
        or "none"
    )
    return f"; against the control arm (same seeds, McNemar p < 0.05; Δ ×100 [paired 95 % CI]): {named}"


def split_title(split: str) -> str:
    """A split's title: its factor's own title (factor registry), else the split name."""
    return FACTORS[split].title if split in FACTORS else split


def split_order(layouts: dict[str, dict], key: str) -> list[str]:
    """Splits present in any policy's `key` section: the registry's visual factors first, in its order."""
    present = {s for layout in layouts.values() for s in layout[key]}
    return [s for s in visual_factors() if s in present] + sorted(present - set(visual_factors()))


def task_order(splits: Sequence[str]) -> list[str]:
    """Splits grouped by task (the default task first), each task's in the factor registry's order."""
    return sorted(
        splits,
        key=lambda s: (
            split_task(s)[0] != DEFAULT_TASK,
            split_task(s)[0],
            (*visual_factors(), split_task(s)[1]).index(split_task(s)[1]),
        ),
    )
