"""The 95 % interval of `cv_excess` (metrics.json `cv_excess_ci95`): a parametric bootstrap whose coverage is
validated by simulation (docs/statistics.md, "An interval for cv_excess"; `python -m benchmarks.cv_excess_interval`).

The cells' success rates, shrunk toward their context's mean so that their own CV is the split's cv_excess
(s = cv_excess / cv: the spread the noise does not explain), are the bootstrap's truth; each bootstrap table draws
every episode from its cell's shrunk rate and computes cv_excess exactly as the split's (CV against its
within-(context, repeat) permutation floor). The interval is the bootstrap's 2.5 and 97.5 % quantiles. A plain
bootstrap around the observed rates would be centred on the noise-inflated CV; shrinking first removes that.
"""

from __future__ import annotations

import numpy as np

from roboview.eval.statistics.tables import CellTable, conditional_cv, excess, group_sum

BOOT_PERM = 100  # within-block permutations behind each bootstrap table's noise floor


def cv_excess_interval(
    table: CellTable,
    ctx: np.ndarray,
    cv: float | None,
    cv_excess: float | None,
    n_boot: int,
    epsilon: float,
    rng,
) -> list[float] | None:
    """[lo, hi] of cv_excess for a single-factor split's cell table (`ctx`: each cell's context code); None without
    a cv, or with n_boot = 0."""
    if not n_boot or cv is None or cv_excess is None:
        return None
    sr, n = table.sr, table.n
    mean = (group_sum(sr, ctx) / np.bincount(ctx))[ctx]
    shrunk = np.clip(mean + (cv_excess / cv if cv > 0 else 0.0) * (sr - mean), 0.0, 1.0)
    cell = table.episodes["cell"].to_numpy()
    blocks = table.blocks(["context_id"])  # the same design for every bootstrap table

    def statistic(rates: np.ndarray) -> np.ndarray:
        return conditional_cv(rates, ctx, epsilon).mean(axis=-1)

    stars = np.empty(n_boot)
    for b in range(n_boot):
        success = (rng.random(len(cell)) < shrunk[cell]).astype(np.int64)
        null = statistic(table.permuted_k(["context_id"], BOOT_PERM, rng, success, blocks) / n).mean()
        stars[b] = excess(float(statistic(group_sum(success, cell) / n)), float(null))
    lo, hi = np.quantile(stars, [0.025, 0.975])
    return [float(lo), float(hi)]
