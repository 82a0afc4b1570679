"""Success by task context factor: does the instruction's wording (or the shape, or where the object starts)
change a policy's success?

The benchmark's contexts come from variation subspaces (per_subspace mode): in the instruction subspace
only the instruction varies, every other context factor at its baseline. For each context factor f this
module takes the episodes of f's subspace across every single-factor split — the same visual conditions
under each value of f — and reports SR per value of f with its Clopper–Pearson interval, plus a likelihood-ratio
test of a binomial GLM `f + condition` against `condition`, where a condition is a (split, visual value)
pair. The reference is χ², or, when cells are sparse, permutations of f's labels among the episodes of
one (condition, repeat) — the same calibration as the splits' `p_value`.

A language-blind policy (ACT) sees three paraphrases as one input: any difference between instructions is
context noise and the test should not reject. A language-conditioned policy (SmolVLA, π0) that succeeds
under one paraphrase and fails under another is sensitive to wording, which this makes visible.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.statistics import significance as stats
from roboview.eval.statistics.tables import CellTable, MetricsConfig, rate_ci95, value_order
from roboview.variation.factors import DEFAULT_TASK, baselines, context_factors


def _subspace(episodes: pd.DataFrame, task: str, factor: str) -> pd.DataFrame:
    """Single-factor-split episodes of `task` whose other context factors sit at their baselines."""
    rows = episodes[~episodes["factor"].astype(str).str.contains("|", regex=False)]
    if "task" in rows:
        rows = rows[rows["task"].fillna(DEFAULT_TASK) == task]
    elif task != DEFAULT_TASK:
        return rows.iloc[0:0]
    base = baselines(task)
    for other in context_factors(task):
        if other != factor and other in rows:
            rows = rows[rows[other].astype(str) == base[other]]
    return rows


def context_factor_metrics(
    episodes: pd.DataFrame, task: str, factor: str, cfg: MetricsConfig = MetricsConfig()
) -> dict[str, Any] | None:
    """SR per value of one context factor over its subspace, and the test; None with fewer than 2 values."""
    rows = _subspace(episodes, task, factor)
    if factor not in rows or rows[factor].nunique() < 2:
        return None
    eps = rows[[factor, "split", "value", "repeat", "success"]].astype({factor: str, "value": str}).copy()
    eps["success"] = eps["success"].astype(np.int64)
    table = CellTable.build(eps, (factor,), [factor, "split", "value"])
    permuted = table.permuted_k(["split", "value"], cfg.n_glm, cfg.rng(f"{task}:{factor}", "context"))
    test = stats.factor_lrt(
        table.k, table.n, table.codes([factor]), table.codes(["split", "value"]), permuted
    )
    per_value = {}
    for value in value_order(factor, eps[factor].unique()):
        mine = eps[eps[factor] == value]
        k, n = int(mine["success"].sum()), len(mine)
        per_value[value] = {"sr": k / n, "sr_ci95": rate_ci95(k, n), "n_episodes": n}
    return {
        "task": task,
        "n_episodes": len(eps),
        "n_conditions": int(eps.groupby(["split", "value"]).ngroups),
        **stats.lrt_fields(test),
        "per_value": per_value,
    }


def context_breakdown(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """{factor: context_factor_metrics} for every context factor of every task in `episodes`."""
    tasks = episodes["task"].fillna(DEFAULT_TASK).unique() if "task" in episodes else [DEFAULT_TASK]
    out: dict[str, Any] = {}
    for task in tasks:
        for factor in context_factors(str(task)):
            if factor in episodes:
                found = context_factor_metrics(episodes, str(task), factor, cfg)
                if found is not None:
                    out[factor] = found
    return out
