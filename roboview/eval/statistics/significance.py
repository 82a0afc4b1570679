"""Statistical tests behind the bias metrics: does success depend on a factor, which values, and
do two factors interact (docs/formats.md, "Metrics"). Libraries do the statistics:
binomial GLMs from statsmodels, Cochran–Mantel–Haenszel from statsmodels, Benjamini–Hochberg and
the χ² / non-central χ² laws from scipy. This module only arranges tables for them.

Tables are *cells*: success counts `k` out of `n` episodes, with integer codes (0..G-1) saying
which value / context / other factor each cell belongs to.

Why permutation calibration exists: the χ² law of a likelihood-ratio statistic is asymptotic.
With a handful of repeats per cell and success rates near 0 or 1 (the usual benchmark table) the
expected counts are tiny and the χ² reference is off, so such tables ("sparse": Cochran's rule,
more than 20 % of informative cells expect fewer than 5 successes or failures) get the LRT's
reference distribution from within-block permutations of value labels instead (an exact test).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import statsmodels.api as sm
from scipy import stats
from statsmodels.stats.contingency_tables import StratifiedTable, mcnemar
from threadpoolctl import threadpool_limits

from roboview.eval.statistics.batch_glm import design_llf, spanning_columns, value_lrt
from roboview.eval.statistics.tables import SEQUENTIAL_H

SPARSE_EXPECTED = 5.0  # Cochran: expected counts below this make χ² approximations doubtful
SPARSE_FRACTION = 0.2  # ... in more than this fraction of the cells
_PERM_TOLERANCE = 1e-9  # float noise when a permuted table reproduces the observed statistic
MAX_BATCH = 20_000  # null draws held at once by a sequential p-value


def design_matrix(codes: Sequence[np.ndarray]) -> np.ndarray:
    """Intercept plus treatment-coded dummies (first level dropped) of each factor's codes."""
    columns = [np.ones(len(codes[0]))]
    for code in codes:
        levels = np.unique(code)
        columns += [(code == level).astype(float) for level in levels[1:]]
    return np.column_stack(columns)


def interaction_codes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Codes of the (a, b) combinations present: the A×B term of a GLM."""
    return np.unique(np.stack([a, b], axis=1), axis=0, return_inverse=True)[1].ravel()


def binomial_llf(k: np.ndarray, n: np.ndarray, exog: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Log-likelihood and fitted probabilities of a binomial GLM (logit link) of k successes in n.

    Separated data (a cell or level with every episode failing) sends coefficients to ±∞; the
    log-likelihood still converges to its supremum, which is what a likelihood-ratio test needs.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # perfect-separation and convergence chatter, see above
        result = sm.GLM(np.column_stack([k, n - k]), exog, family=sm.families.Binomial()).fit(maxiter=100)
        # llf and fitted values are lazy: computed here, inside the quiet block.
        return float(result.llf), np.asarray(result.fittedvalues), np.asarray(result.params)


def lrt_statistic(k: np.ndarray, n: np.ndarray, full: np.ndarray, reduced: np.ndarray) -> float:
    """2 (ℓ_full − ℓ_reduced), clipped at 0 (the nested fit can only be worse, up to solver noise)."""
    return max(0.0, 2.0 * (binomial_llf(k, n, full)[0] - binomial_llf(k, n, reduced)[0]))


def is_sparse(n: np.ndarray, p: np.ndarray) -> bool:
    """Cochran's rule on the cells' expected successes and failures under the null fit."""
    expected = np.minimum(n * p, n * (1 - p))
    return bool(np.mean(expected < SPARSE_EXPECTED) > SPARSE_FRACTION)


def informative(k: np.ndarray, n: np.ndarray, strata: np.ndarray) -> np.ndarray:
    """Mask of cells whose stratum has both outcomes: an all-fail or all-succeed stratum carries no
    information about the factor and would send its own coefficient to ±∞."""
    ks = np.bincount(strata, weights=k)
    ns = np.bincount(strata, weights=n)
    return ((ks > 0) & (ks < ns))[strata]


@dataclass(frozen=True)
class LRT:
    """A likelihood-ratio test: statistic, degrees of freedom, p-value and how it was calibrated."""

    statistic: float
    df: int
    p_value: float
    # "asymptotic" (χ²), "permutation", "parametric_bootstrap", or "permutation+scaled_chi2_tail": beyond the
    # permutations' floor, χ² stretched over their upper quantiles (`factor_lrt`).
    method: str
    # Calibrated by draws none of which reached the statistic: p is the floor 1 / (draws + 1).
    at_floor: bool = False
    # Permutation draws behind a sequential p-value (0: a fixed set, or none).
    draws: int = 0


def lrt_fields(test: LRT | None) -> dict[str, Any]:
    """A test as metrics.json stores it: p_value, p_value_method, p_value_at_floor and lrt {statistic, df};
    every field None without a test."""
    if test is None:
        return {"p_value": None, "p_value_method": None, "p_value_at_floor": None, "lrt": None}
    return {
        "p_value": test.p_value,
        "p_value_method": test.method,
        "p_value_at_floor": test.at_floor,
        "lrt": {"statistic": test.statistic, "df": test.df} | ({"draws": test.draws} if test.draws else {}),
    }


@threadpool_limits.wrap(limits=1, user_api="blas")  # hundreds of small refits: threads only contend
def factor_lrt(
    k: np.ndarray,
    n: np.ndarray,
    value: np.ndarray,
    strata: np.ndarray,
    permuted_k: np.ndarray | None,
    more: Callable[[int], np.ndarray] | None = None,
    max_draws: int = 0,
    stretch_tail: bool = False,
) -> LRT | None:
    """Does success depend on `value`? Binomial GLM `value + strata` against `strata`.

    `permuted_k` (n_perm, n_cells): success counts with value labels shuffled within blocks; used
    as the reference distribution when the table is sparse. `more(size)`: further such permutations, drawn
    (Besag–Clifford, `sequential_p`) while fewer than SEQUENTIAL_H of the refits reach the observed statistic, up
    to `max_draws` in all, so a strong effect resolves below 1 / (len(permuted_k) + 1); else, with `stretch_tail`,
    a statistic none of them reaches gets the stretched χ² tail's p (`tail_scale`). Without either, p is the plain
    permutation p-value (1 + exceedances) / (1 + draws). None when no stratum is informative.
    """
    keep = informative(k, n, strata)
    if not keep.any():
        return None
    _, value_c = np.unique(value[keep], return_inverse=True)
    _, strata_c = np.unique(strata[keep], return_inverse=True)
    full, reduced = design_matrix([strata_c, value_c]), design_matrix([strata_c])
    df = full.shape[1] - reduced.shape[1]
    if df == 0:
        return None
    observed = lrt_statistic(k[keep], n[keep], full, reduced)
    _, p_null, _ = binomial_llf(k[keep], n[keep], reduced)
    if permuted_k is None or not is_sparse(n[keep], p_null):
        return LRT(observed, df, float(stats.chi2.sf(observed, df)), "asymptotic")
    refits, reference = _null_refits(k, n, keep, value_c, strata_c, (full, reduced))
    more_null = None if more is None else lambda size: refits(more(size))
    test = _permutation_lrt(reference, df, refits(permuted_k), more_null, max_draws, stretch_tail)
    return dataclasses.replace(test, statistic=observed)


def _null_refits(
    k: np.ndarray,
    n: np.ndarray,
    keep: np.ndarray,
    value: np.ndarray,
    strata: np.ndarray,
    fits: tuple[np.ndarray, np.ndarray],
) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
    """(the LRT statistics of permuted tables (rows of successes over all cells), the observed statistic as they
    are to be compared with it) for `factor_lrt`, whose informative cells `keep` carry codes `value` and `strata`;
    `fits`: its full and reduced designs."""
    nk = n[keep]
    if len(np.unique(value * (strata.max() + 1) + strata)) == len(value):
        # One cell per (value, stratum): the permuted tables share one layout, and their refits are a single
        # batched Newton solve (`batch_glm.value_lrt`, checked against statsmodels' fits). The observed statistic
        # is compared with them as that solver computes it, so a permutation reproducing the table ties exactly;
        # the statistic reported stays statsmodels'.
        def batched(batch: np.ndarray) -> np.ndarray:
            return value_lrt(batch[:, keep], nk, value, strata)

        return batched, float(batched(k[None])[0])
    # Several cells per (value, stratum): the same fits for any one design (`batch_glm.design_llf`, checked against
    # statsmodels' fits), all permuted tables together.
    full, reduced = fits

    def refits(batch: np.ndarray) -> np.ndarray:
        return np.maximum(
            0.0, 2.0 * (design_llf(batch[:, keep], nk, full) - design_llf(batch[:, keep], nk, reduced))
        )

    return refits, float(refits(k[None])[0])


def _permutation_lrt(
    observed: float,
    df: int,
    null: np.ndarray,
    more: Callable[[int], np.ndarray] | None,
    max_draws: int,
    stretch_tail: bool,
) -> LRT:
    """The permutation-calibrated LRT from its first null draws `null`. Where none reaches the statistic, p below
    their floor 1 / (draws + 1) comes from more draws (`more`, Besag–Clifford, up to `max_draws`) when asked, else
    from the χ² tail stretched over the null's upper quantiles (`tail_scale`)."""
    if _reaches(observed, null).any():
        return LRT(observed, df, permutation_p(observed, null), "permutation")
    if more is not None and max_draws > len(null):  # more permutations, while fewer than h reach it
        mc = sequential_p(observed, null, more, SEQUENTIAL_H, max_draws)
        return LRT(observed, df, mc.p_value, "permutation", mc.at_floor, mc.draws)
    tail = float(stats.chi2.sf(observed / tail_scale(null, df), df)) if stretch_tail else 1.0
    if tail < 1 / (len(null) + 1):
        return LRT(observed, df, tail, "permutation+scaled_chi2_tail")
    return LRT(observed, df, permutation_p(observed, null), "permutation", True)


def tail_scale(null: np.ndarray, df: int, levels: Sequence[float] = (0.9, 0.95, 0.99)) -> float:
    """The factor c ≥ 1 by which χ²(df) must be stretched to lie at or above the permutation null of an LRT at its
    upper quantiles `levels` (sparse tables give a heavier null than χ²): p = P(c·χ² ≥ observed) then errs on the
    large side wherever the draws can see."""
    return float(max(1.0, np.max(np.quantile(null, levels) / stats.chi2.ppf(levels, df))))


def _reaches(observed: float, null: np.ndarray) -> np.ndarray:
    return null >= observed - _PERM_TOLERANCE * max(1.0, abs(observed))


def permutation_p(observed: float, null: np.ndarray) -> float:
    """(1 + #{null ≥ observed}) / (1 + B): never 0, exact for exchangeable draws."""
    return float((1 + np.sum(_reaches(observed, null))) / (1 + len(null)))


@dataclass(frozen=True)
class MonteCarloP:
    """A Monte Carlo p-value and what it rests on. `at_floor`: no draw reached the observed statistic, so
    the true p may be smaller than `p_value` = 1 / (draws + 1); report it as "≤ p_value"."""

    p_value: float
    draws: int
    exceedances: int

    @property
    def at_floor(self) -> bool:
        return self.exceedances == 0


def sequential_p(
    observed: float, first: np.ndarray, more, h: int = 20, max_draws: int = 100_000
) -> MonteCarloP:
    """Besag & Clifford's (1991) sequential Monte Carlo p-value.

    Null statistics are drawn a batch at a time (`first`, then `more(size)`, each batch as large as all before
    it, at most MAX_BATCH, until `max_draws`) and
    sampling stops at the draw L that brings the h-th one reaching `observed`: p = h / L. If `max_draws` come
    first with s < h reaching it, p = (s + 1) / (max_draws + 1), the fixed-B p-value. Both are valid
    p-values; a weak effect stops after a few draws, a strong one draws up to `max_draws`, so the floor
    1 / (max_draws + 1) binds only where the evidence is that strong."""
    seen = exceed = 0
    batch = first
    while True:
        hits = np.cumsum(_reaches(observed, batch))
        if exceed + (hits[-1] if len(hits) else 0) >= h:
            at = int(np.searchsorted(hits, h - exceed)) + 1  # draws of this batch up to the h-th exceedance
            return MonteCarloP(h / (seen + at), seen + at, h)
        seen += len(batch)
        exceed += int(hits[-1]) if len(hits) else 0
        if seen >= max_draws or more is None:
            return MonteCarloP((exceed + 1) / (seen + 1), seen, exceed)
        batch = more(min(max(len(first), seen), MAX_BATCH, max_draws - seen))  # doubling, memory-bounded


@threadpool_limits.wrap(limits=1, user_api="blas")
def interaction_lrt(
    k: np.ndarray,
    n: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    strata: np.ndarray,
    n_boot: int,
    rng: np.random.Generator,
) -> tuple[LRT | None, np.ndarray | None]:
    """A×B against A + B (both + strata), and parametric-bootstrap tables from the additive fit.

    Returns the test and (n_boot, n_cells) success counts drawn from the fitted additive model: the
    reference for the LRT when the table is sparse, and the null tables of IEC. The bootstrap
    tables cover every cell; uninformative strata keep their observed (constant) outcome.
    """
    keep = informative(k, n, strata)
    if not keep.any():
        return None, None
    codes = [np.unique(x[keep], return_inverse=True)[1] for x in (strata, a, b)]
    additive = design_matrix(codes)
    # The A×B dummies span A's and B's, and missing combinations make more of them dependent: the full model is
    # fitted on the columns that span it (statsmodels' pinv-based fit of the redundant design can stop far below
    # the additive model's maximum on a separated table, which clips the statistic to 0).
    full = spanning_columns(design_matrix([*codes, interaction_codes(codes[1], codes[2])]))
    df = full.shape[1] - np.linalg.matrix_rank(additive)
    _, p_add, _ = binomial_llf(k[keep], n[keep], additive)
    draws = np.tile(k, (n_boot, 1))
    draws[:, keep] = rng.binomial(n[keep], p_add, size=(n_boot, int(keep.sum())))
    if df == 0:
        return None, draws
    observed = lrt_statistic(k[keep], n[keep], full, additive)
    if not is_sparse(n[keep], p_add):
        return LRT(observed, int(df), float(stats.chi2.sf(observed, df)), "asymptotic"), draws

    # The observed table's and the bootstrap tables' statistics in one batched solve (`batch_glm.design_llf`,
    # checked against statsmodels' fits): the observed statistic is compared with them as that solver computes it.
    tables = np.vstack([k[None, keep], draws[:, keep]])
    statistics = np.maximum(
        0.0, 2.0 * (design_llf(tables, n[keep], full) - design_llf(tables, n[keep], additive))
    )
    reference, null = float(statistics[0]), statistics[1:]
    return LRT(
        observed,
        int(df),
        permutation_p(reference, null),
        "parametric_bootstrap",
        not _reaches(reference, null).any(),
    ), draws


@dataclass(frozen=True)
class ValueTest:
    """One value against the others, Mantel–Haenszel over strata (None where undefined)."""

    odds_ratio: float | None
    odds_ratio_ci95: list[float] | None
    p_value: float | None


def value_vs_rest(
    k_value: np.ndarray, n_value: np.ndarray, k_all: np.ndarray, n_all: np.ndarray
) -> ValueTest:
    """Cochran–Mantel–Haenszel: a value's episodes against the other values', per stratum.

    Arrays run over strata: the value's successes / episodes and everyone's. Strata without both
    groups or without both outcomes carry no information and are left out. The odds ratio and its
    interval are statsmodels' Mantel–Haenszel estimate; the p-value is the *exact* conditional test
    of the same hypothesis (`exact_stratified_p`): the asymptotic CMH χ² is wildly anti-conservative
    on benchmark tables (a value failing 2 of 2 where 5 of 141 fail per block: χ² says 1.6e-13, the
    exact probability is 1.3e-3).
    """
    k_rest, n_rest = k_all - k_value, n_all - n_value
    use = (n_value > 0) & (n_rest > 0) & (k_all > 0) & (k_all < n_all)
    if not use.any():
        return ValueTest(None, None, None)
    tables = np.array([[k_value, n_value - k_value], [k_rest, n_rest - k_rest]], dtype=float)[:, :, use]
    table = StratifiedTable(tables)
    with np.errstate(divide="ignore", invalid="ignore"):
        odds = _finite(table.oddsratio_pooled)
        ci = [_finite(x) for x in table.oddsratio_pooled_confint()]
    p = exact_stratified_p(k_value[use], n_value[use], k_all[use], n_all[use])
    return ValueTest(odds, None if None in ci else ci, p)


@functools.lru_cache(maxsize=4096)
def hypergeom_pmf(n: int, k: int, kv: int) -> np.ndarray:
    """P(x successes among a value's `kv` episodes | `k` of a stratum's `n` succeed), x = 0 … kv (scipy's
    hypergeom): strata repeat their margins across values and splits, so each is computed once."""
    pmf = stats.hypergeom.pmf(np.arange(kv + 1), n, k, kv)
    pmf.flags.writeable = False
    return pmf


def exact_stratified_p(
    k_value: np.ndarray, n_value: np.ndarray, k_all: np.ndarray, n_all: np.ndarray
) -> float:
    """Exact conditional test of "common odds ratio 1" over strata of 2×2 tables.

    Given every stratum's margins, the value's successes in a stratum are hypergeometric (scipy); their
    total is the convolution over strata. Two-sided p: the probability of totals no more likely than
    the observed one (the rule of R's `mantelhaen.test(exact = TRUE)` and Fisher's exact test).
    """
    dist = np.ones(1)
    for k, n, kv in zip(k_all.astype(int), n_all.astype(int), n_value.astype(int)):
        dist = np.convolve(dist, hypergeom_pmf(int(n), int(k), int(kv)))
    observed = dist[int(k_value.sum())]
    return float(min(1.0, dist[dist <= observed * (1 + 1e-7)].sum()))


def _finite(x: float) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def benjamini_hochberg(p_values: Sequence[float | None]) -> list[float | None]:
    """BH q-values (scipy) over the defined p-values; None stays None."""
    defined = [i for i, p in enumerate(p_values) if p is not None]
    q: list[float | None] = [None] * len(p_values)
    if defined:
        adjusted = stats.false_discovery_control([p_values[i] for i in defined], method="bh")
        for i, value in zip(defined, adjusted):
            q[i] = float(value)
    return q


def paired_success_test(a: np.ndarray, b: np.ndarray) -> float:
    """McNemar's test on episodes paired by (instance, repeat) — same seed, same scene, two policies.

    Exact binomial when fewer than 25 pairs disagree, χ² with continuity correction otherwise.
    """
    table = [[np.sum(a & b), np.sum(a & ~b)], [np.sum(~a & b), np.sum(~a & ~b)]]
    discordant = table[0][1] + table[1][0]
    if discordant == 0:
        return 1.0
    return float(mcnemar(table, exact=discordant < 25, correction=True).pvalue)


def lrt_power(
    n_values: int,
    n_contexts: int,
    repeats: int,
    tau: float,
    sr: float,
    alpha: float = 0.05,
    draws: int = 2000,
) -> float:
    """Power of the `value + context` LRT against value effects β_v ~ N(0, τ²) on the logit scale.

    For given effects the LRT is non-central χ² with df = |V| − 1 and non-centrality
    λ = n · |C| · Σ_v w_v (β_v − β̄_w)², w_v = p_v (1 − p_v) (the Fisher information per episode,
    β̄_w the w-weighted mean); the power is averaged over `draws` seeded draws of the effects,
    because power is not linear in λ. Asymptotic: sparse tables, permutation-calibrated, fall short
    of it by up to ≈ 0.1 (docs/statistics.md).
    """
    df = n_values - 1
    if df < 1:
        raise ValueError(f"a factor needs ≥ 2 values to be tested, got {n_values}")
    beta = np.random.default_rng(0).normal(0.0, tau, (draws, n_values))
    p = 1 / (1 + np.exp(-(np.log(sr / (1 - sr)) + beta)))
    w = p * (1 - p)
    lam = repeats * n_contexts * ((w * beta**2).sum(axis=1) - (w * beta).sum(axis=1) ** 2 / w.sum(axis=1))
    return float(stats.ncx2.sf(stats.chi2.ppf(1 - alpha, df), df, lam).mean())


def repeats_needed(
    n_values: int,
    n_contexts: int,
    tau: float,
    sr: float,
    power: float = 0.8,
    alpha: float = 0.05,
    max_repeats: int = 1000,
) -> int | None:
    """Fewest repeats per instance reaching `power`; None if even `max_repeats` does not."""
    for repeats in range(1, max_repeats + 1):
        if lrt_power(n_values, n_contexts, repeats, tau, sr, alpha) >= power:
            return repeats
    return None


def logistic_trend(
    xs: np.ndarray, successes: np.ndarray, n: np.ndarray
) -> tuple[np.ndarray, float, float] | None:
    """Binomial GLM (logit) success ~ x fitted to per-value counts at numeric values `xs`: (fitted SR on 50
    points from min to max of xs, slope per unit of x, its Wald p). None with fewer than 3 values, no episode,
    or no failure or no success (nothing to fit)."""
    if len(xs) < 3 or n.sum() == 0 or successes.sum() in (0, n.sum()):
        return None
    model = sm.GLM(
        np.column_stack([successes, n - successes]), sm.add_constant(xs), family=sm.families.Binomial()
    )
    fit = model.fit()
    grid = np.linspace(xs.min(), xs.max(), 50)
    return fit.predict(sm.add_constant(grid)), float(fit.params[1]), float(fit.pvalues[1])
