"""The statistics' shared vocabulary: the metrics config and its random streams, binomial intervals, the CV's
group arithmetic, a split's episodes as cells (`CellTable`) and the order a factor's values are listed in.

Below `roboview.eval.statistics.metrics` (per-split metrics), `roboview.eval.statistics.context` (success by context factor) and
`roboview.eval.statistics.compare` (paired policy comparisons), which build on it.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from roboview.variation.factors import FACTORS

EPSILON = 1e-6
# Exceedances that stop a sequential Monte Carlo p-value (Besag–Clifford): its relative error is ≈ 1/√h.
SEQUENTIAL_H = 20
Z95 = 1.959963984540054  # standard normal 97.5 % quantile


@dataclass(frozen=True)
class MetricsConfig:
    """How metrics are computed; the same config and table always give the same numbers."""

    # ε in the CV and IEC denominators (default 1e-6).
    epsilon: float = EPSILON
    # Within-block permutations behind cv_null and p_value_cv.
    n_perm: int = 1000
    # Draws behind GLM calibration: permutations for a sparse p_value, additive-model tables for
    # iec_null and a sparse p_interaction (each draw refits a GLM, so fewer than n_perm).
    n_glm: int = 200
    # Seed of the permutation and bootstrap generators (one stream per split and purpose).
    seed: int = 0
    # Most within-block permutations behind p_value_cv: beyond the first n_perm, more are drawn (n_perm at a
    # time) while fewer than SEQUENTIAL_H reach the observed CV (Besag–Clifford), so a strong bias gets a
    # p-value down to 1 / (max_perm + 1) instead of 1 / (n_perm + 1).
    max_perm: int = 20_000
    # A permutation-calibrated GLM p_value that none of its n_glm refits reaches: 0 reads it from the χ² tail
    # stretched over the refits' upper quantiles (docs/statistics.md); N > n_glm draws more permutations instead,
    # while fewer than SEQUENTIAL_H reach the statistic, down to 1 / (N + 1) (each one a GLM refit: slow).
    max_glm: int = 0
    # Bootstrap tables behind cv_excess_ci95 (roboview.eval.statistics.intervals); 0: no interval.
    n_boot: int = 200

    def __post_init__(self) -> None:
        if not self.epsilon > 0:
            raise ValueError(f"epsilon={self.epsilon} must be > 0 (it keeps CV finite at SR = 0)")
        if self.n_perm < 1 or self.n_glm < 1:
            raise ValueError(f"n_perm={self.n_perm} and n_glm={self.n_glm} must be ≥ 1")
        if self.max_perm < self.n_perm:
            raise ValueError(f"max_perm={self.max_perm} must be ≥ n_perm={self.n_perm}")
        if self.n_boot < 0:
            raise ValueError(f"n_boot={self.n_boot} must be ≥ 0 (0: no cv_excess interval)")
        if self.max_glm and self.max_glm < self.n_glm:
            raise ValueError(f"max_glm={self.max_glm} must be 0 (the χ² tail) or ≥ n_glm={self.n_glm}")
        if self.seed < 0:
            raise ValueError(f"seed={self.seed} must be ≥ 0")

    def rng(self, split: str, purpose: str) -> np.random.Generator:
        """The random stream of one (seed, split, purpose): a split's numbers never depend on which others
        exist."""
        return np.random.default_rng([self.seed, zlib.crc32(f"{split}:{purpose}".encode())])


def rate_interval(
    successes: int | np.ndarray, n: int, alpha: float = 0.05
) -> tuple[float, float] | tuple[np.ndarray, np.ndarray] | None:
    """The success rate's Clopper–Pearson ("exact") interval, successes/n (statsmodels `proportion_confint`,
    method "beta"); None when n = 0. It covers the true rate with probability ≥ 1 − alpha at every rate and n, at
    the ceiling too, where Wilson's falls to 0.91 (n = 50, rate 0.99; docs/statistics.md, by exact enumeration).
    `successes` may be an array (one interval per count, as arrays). 8/10 → (0.444, 0.975); 10/10 → (0.692, 1.0)."""
    if n <= 0:
        return None
    from statsmodels.stats.proportion import proportion_confint

    lo, hi = proportion_confint(successes, n, alpha=alpha, method="beta")
    if np.ndim(lo):
        return np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return float(lo), float(hi)


def rate_ci95(successes: int, n: int) -> list[float] | None:
    """`rate_interval` at 95 % as metrics.json stores it: [low, high] (None when n = 0); 8/10 → [0.444, 0.975]."""
    ci = rate_interval(int(successes), n)
    return None if ci is None else [ci[0], ci[1]]


def paired_difference_interval(
    both: int | np.ndarray,
    first_only: int | np.ndarray,
    second_only: int | np.ndarray,
    neither: int | np.ndarray,
    alpha: float = 0.05,
) -> tuple[float, float] | tuple[np.ndarray, np.ndarray] | None:
    """Newcombe's hybrid score interval (Newcombe 1998, Statistics in Medicine 17:2635, method 10) for the
    difference of two paired success rates, (both + first_only)/n − (both + second_only)/n over n pairs: the Wilson
    limits of the two marginal rates (statsmodels `proportion_confint`, method "wilson") combined with the pairs'
    correlation φ, shrunk toward 0 by n/2 as Newcombe's method 10 does (0 where a margin is empty). Neither
    statsmodels nor scipy ships a paired-difference interval. Counts may be arrays (one interval each, as arrays);
    None when n = 0. Newcombe's worked example 20, 12, 2, 16 → (0.0562, 0.3292)."""
    from statsmodels.stats.proportion import proportion_confint

    a, b, c, d = (np.asarray(x, dtype=float) for x in (both, first_only, second_only, neither))
    n = a + b + c + d
    if np.ndim(n) == 0 and n <= 0:
        return None
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = proportion_confint(a + b, n, alpha=alpha, method="wilson")
    l2, u2 = proportion_confint(a + c, n, alpha=alpha, method="wilson")
    det = a * d - b * c
    margins = (a + b) * (c + d) * (a + c) * (b + d)
    shrunk = np.where(det > 0, np.maximum(det - n / 2, 0.0), det)
    phi = np.divide(shrunk, np.sqrt(margins), out=np.zeros_like(n), where=margins > 0)
    down1, up2, up1, down2 = p1 - l1, u2 - p2, u1 - p1, p2 - l2
    lo = p1 - p2 - np.sqrt(np.maximum(0.0, down1**2 - 2 * phi * down1 * up2 + up2**2))
    hi = p1 - p2 + np.sqrt(np.maximum(0.0, up1**2 - 2 * phi * up1 * down2 + down2**2))
    lo, hi = np.clip(lo, -1.0, 1.0), np.clip(hi, -1.0, 1.0)
    if np.ndim(lo):
        return lo, hi
    return float(lo), float(hi)


def paired_difference_ci95(first: np.ndarray, second: np.ndarray) -> list[float] | None:
    """`paired_difference_interval` at 95 % of SR(first) − SR(second) over paired outcomes (two boolean arrays, one
    entry per pair), as metrics.json stores it: [low, high]; None without pairs."""
    first, second = np.asarray(first, dtype=bool), np.asarray(second, dtype=bool)
    if not len(first):
        return None
    ci = paired_difference_interval(
        int(np.sum(first & second)),
        int(np.sum(first & ~second)),
        int(np.sum(~first & second)),
        int(np.sum(~first & ~second)),
    )
    return None if ci is None else [ci[0], ci[1]]


def conditional_cv(sr: np.ndarray, groups: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """σ / (μ + ε) of `sr` within each group (the paper's CCV), vectorized over leading axes.

    `sr` has shape (..., n_items); `groups` gives each item's group code 0..G-1 (every code
    present). Returns shape (..., G). Used for CV(V|c) and, one level up, for IEC.
    """
    counts = np.bincount(groups)
    mean = group_sum(sr, groups) / counts
    var = group_sum((sr - mean[..., groups]) ** 2, groups) / counts
    return np.sqrt(var) / (mean + epsilon)


def group_sum(x: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Sum of x's last axis within each group code (reduceat over a stable sort)."""
    order = np.argsort(groups, kind="stable")
    starts = np.searchsorted(groups[order], np.arange(groups.max() + 1))
    return np.add.reduceat(x[..., order], starts, axis=-1)


def codes(frame: pd.DataFrame, columns: Sequence[str]) -> np.ndarray:
    """Group code 0..G-1 of each row by `columns` (sorted order)."""
    return frame.groupby(list(columns), sort=True).ngroup().to_numpy()


def excess(observed: float, null: float) -> float:
    """√max(0, observed² − null²): the part of a dispersion not explained by the null's noise."""
    return math.sqrt(max(0.0, observed * observed - null * null))


def value_order(factor: str, values: Sequence[str]) -> list[str]:
    """`values` in the factor registry's order (rings, yaw-major, k) where the factor is known, then the rest
    sorted; a value listed twice is listed once."""
    known = FACTORS[factor].values if factor in FACTORS else ()
    present = set(values)
    return [v for v in known if v in present] + sorted(present - set(known))


@dataclass(frozen=True)
class CellTable:
    """Episodes grouped into cells (one per combination of the key columns, e.g. value × context), each
    episode keeping its cell and repeat: what the CV, its permutation null and the GLM tests read."""

    factors: tuple[str, ...]
    cells: pd.DataFrame  # one row per cell: the key columns, n (episodes) and k (successes)
    episodes: pd.DataFrame  # one row per episode: the key columns, repeat, success (0/1) and cell

    @classmethod
    def build(cls, episodes: pd.DataFrame, factors: Sequence[str], keys: Sequence[str]) -> CellTable:
        """Cells of `episodes` by `keys` (sorted); `episodes` holds the key columns, repeat and success."""
        missing = [c for c in (*keys, "repeat", "success") if c not in episodes.columns]
        if missing:
            raise ValueError(
                f"episodes lack column(s) {', '.join(missing)}; a cell table needs the keys "
                f"{list(keys)}, repeat and success"
            )
        eps = episodes.copy()
        eps["cell"] = codes(eps, keys)
        cells = eps.groupby("cell", sort=True).agg(
            n=("success", "size"), k=("success", "sum"), **{key: (key, "first") for key in keys}
        )
        return cls(tuple(factors), cells.reset_index(drop=True), eps.reset_index(drop=True))

    @property
    def n(self) -> np.ndarray:
        return self.cells["n"].to_numpy()

    @property
    def k(self) -> np.ndarray:
        return self.cells["k"].to_numpy()

    @property
    def sr(self) -> np.ndarray:
        return self.k / self.n

    def codes(self, columns: Sequence[str]) -> np.ndarray:
        """Group code of each cell by `columns` (see `codes`)."""
        return codes(self.cells, columns)

    def permuted_k(
        self,
        within: Sequence[str],
        n_perm: int,
        rng: np.random.Generator,
        success: np.ndarray | None = None,
        blocks: list[np.ndarray] | None = None,
    ) -> np.ndarray:
        """(n_perm, n_cells) success counts with episodes' cell labels shuffled within blocks.

        A block is a combination of `within` columns plus the repeat: under the null every
        episode of a block is exchangeable (the same seed, the same context, any value). `success` replaces the
        episodes' own outcomes (a bootstrap table of the same design); `blocks`, `self.blocks(within)` computed
        once for many calls.
        """
        eps = self.episodes
        success = (eps["success"].to_numpy() if success is None else success).astype(np.int8)
        shuffled = np.empty((n_perm, len(eps)), dtype=np.int8)
        for idx in self.blocks(within) if blocks is None else blocks:
            shuffled[:, idx] = rng.permuted(np.tile(success[idx], (n_perm, 1)), axis=1)
        return group_sum(shuffled.astype(np.int64), eps["cell"].to_numpy())

    def blocks(self, within: Sequence[str]) -> list[np.ndarray]:
        """The episodes' indices in each block of `within` plus the repeat (`permuted_k`), in block order."""
        codes_ = codes(self.episodes, [*within, "repeat"])
        order = np.argsort(codes_, kind="stable")
        bounds = np.searchsorted(codes_[order], np.arange(codes_.max() + 2))
        return [order[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
