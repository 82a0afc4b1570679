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


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """Wilson score interval for successes/n (None when n = 0); 8/10 → (0.490, 0.943)."""
    if n <= 0:
        return None
    p = successes / n
    denom = 1 + z * z / n
    center = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # At 0/n and n/n the bound is exactly 0 or 1; the formula only reaches it up to float noise.
    lo = 0.0 if successes == 0 else max(0.0, center - half)
    hi = 1.0 if successes == n else min(1.0, center + half)
    return lo, hi


def wilson_ci95(successes: int, n: int) -> list[float] | None:
    """`wilson_interval` as metrics.json stores it: [low, high] (None when n = 0); 8/10 → [0.490, 0.943]."""
    ci = wilson_interval(successes, n)
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
