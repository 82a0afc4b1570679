"""Rankings of three or more policies that claim no difference the paired tests do not support.

Per split, policies are ordered by SR (higher first) and by `cv_excess` (lower first). Which pairs differ
comes from the paired tests of `roboview.eval.statistics.compare` (McNemar for SR, the swap permutation test for cv_excess),
Holm-adjusted over the pairs of that split and metric (`holm`). Two outputs say what
the order means:

- **groups**, a compact letter display (insert-absorb, Piepho 2004): policies that share a letter are not
  significantly different;
- **rank range** [best, worst]: 1 + the policies significantly better, and n − the policies significantly
  worse — the ranks the tests leave possible.

Overall, SR is tested on every paired episode of every split at once (McNemar, Holm over pairs); cv_excess is
averaged over splits and ranked without an overall test (its differences are tested per split).
"""

from __future__ import annotations

import itertools
import string
from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.statistics.significance import paired_success_test

ALPHA = 0.05
METRICS = {"sr": ("p_sr", True), "cv_excess": ("p_cv_excess", False)}  # metric → (p key, higher is better)


def holm(pvalues: list[float]) -> np.ndarray:
    """Holm step-down adjusted p-values, in the order given: the k-th smallest times (m − k + 1), made
    non-decreasing and capped at 1 (statsmodels' `multipletests(..., "holm")`, which runs a full garbage
    collection on every call: seconds per ranking in a process that holds many objects)."""
    p = np.asarray(pvalues, dtype=float)
    order = np.argsort(p)
    adjusted = np.empty_like(p)
    adjusted[order] = np.minimum(1.0, np.maximum.accumulate(p[order] * np.arange(len(p), 0, -1)))
    return adjusted


def compact_letters(order: list[str], different: set[frozenset[str]]) -> dict[str, str]:
    """Letters per policy (best first): policies sharing a letter are not significantly different."""
    groups: list[set[str]] = [set(order)]
    for pair in different:
        a, b = tuple(pair)
        split: list[set[str]] = []
        for group in groups:
            split += [group - {a}, group - {b}] if {a, b} <= group else [group]
        unique = [g for i, g in enumerate(split) if g and g not in split[:i]]
        groups = [g for g in unique if not any(g < h for h in unique)]
    rank = {name: i for i, name in enumerate(order)}
    groups.sort(key=lambda g: min(rank[n] for n in g))
    letters = {name: "" for name in order}
    for letter, group in zip(string.ascii_lowercase, groups):
        for name in group:
            letters[name] += letter
    return {name: "".join(sorted(letters[name])) for name in order}


def rank_table(
    values: dict[str, float], pvalues: dict[frozenset[str], float], higher_better: bool, alpha: float = ALPHA
) -> list[dict[str, Any]]:
    """One ranking: policies best first, each with its value, letters and rank range."""
    names = sorted(values, key=lambda n: (-values[n] if higher_better else values[n], n))
    pairs = [p for p in pvalues if pvalues[p] is not None and p <= set(names)]
    adjusted = dict(zip(pairs, holm([pvalues[p] for p in pairs])))
    different = {p for p, q in adjusted.items() if q < alpha}
    letters = compact_letters(names, different)
    out = []
    for name in names:
        better = sum(
            1
            for other in names
            if frozenset((name, other)) in different
            and (values[other] > values[name]) == higher_better
            and values[other] != values[name]
        )
        worse = sum(1 for other in names if frozenset((name, other)) in different) - better
        out.append(
            {
                "policy": name,
                "value": values[name],
                "group": letters[name],
                "rank_range": [1 + better, len(names) - worse],
            }
        )
    return out


def pooled_p_sr(episodes: pd.DataFrame, a: str, b: str) -> float | None:
    wide = (
        episodes[episodes["policy"].isin([a, b])]
        .pivot_table(
            index=["split", "instance_id", "repeat"], columns="policy", values="success", aggfunc="first"
        )
        .dropna()
    )
    if wide.empty:
        return None
    return paired_success_test(wide[a].to_numpy(bool), wide[b].to_numpy(bool))


def rankings(metrics: dict[str, Any], episodes: pd.DataFrame) -> dict[str, Any] | None:
    """`metrics.json` `rankings`: per split and overall, by SR and by cv_excess (three or more policies)."""
    layouts = metrics["policies"]
    if len(layouts) < 3:
        return None
    per_split: dict[str, dict[str, list]] = {}
    splits = sorted({s for layout in layouts.values() for s in layout["splits"]})
    for split in splits:
        comps = {frozenset(c["policies"]): c for c in metrics["comparisons"] if c["split"] == split}
        entry = {}
        for metric, (p_key, higher) in METRICS.items():
            values = {
                name: layout["splits"][split][metric]
                for name, layout in layouts.items()
                if split in layout["splits"] and layout["splits"][split][metric] is not None
            }
            if len(values) >= 3:
                entry[metric] = rank_table(values, {pair: c[p_key] for pair, c in comps.items()}, higher)
        if entry:
            per_split[split] = entry
    names = sorted(layouts)
    overall_sr = {name: float(episodes.loc[episodes["policy"] == name, "success"].mean()) for name in names}
    pooled = {frozenset((a, b)): pooled_p_sr(episodes, a, b) for a, b in itertools.combinations(names, 2)}
    mean_cv = {
        name: float(np.mean(v))
        for name in names
        if (v := [m["cv_excess"] for m in layouts[name]["splits"].values() if m["cv_excess"] is not None])
    }
    overall = {"sr": rank_table(overall_sr, pooled, True)}
    if len(mean_cv) >= 3:
        overall["cv_excess_mean"] = rank_table(mean_cv, {}, False)  # no overall test: one group, full ranges
    return {"alpha": ALPHA, "adjustment": "holm", "splits": per_split, "overall": overall}
