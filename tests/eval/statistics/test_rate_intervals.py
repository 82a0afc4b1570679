"""The success-rate interval (Clopper–Pearson) and the paired difference interval (Newcombe's hybrid score), checked
by exact enumeration of their coverage and against published worked examples (docs/statistics.md, "Intervals")."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.stats.proportion import proportion_confint

from roboview.eval.statistics.compare import control_deltas
from roboview.eval.statistics.tables import (
    paired_difference_ci95,
    paired_difference_interval,
    rate_ci95,
    rate_interval,
)

pytestmark = pytest.mark.fast

# True rates: every 0.001 of (0, 1), and every 0.0001 over 0.95–0.999, where benchmark baselines sit.
GRID = np.unique(np.round(np.concatenate([np.arange(1, 1000) / 1000, np.arange(9500, 9991) / 10000]), 10))


def coverage(lo: np.ndarray, hi: np.ndarray, n: int, p: np.ndarray) -> np.ndarray:
    """Exact coverage at each true rate p of the intervals [lo_k, hi_k], k = 0..n: Σ_k binom.pmf(k, n, p)·[lo_k ≤ p ≤
    hi_k]. Both ends rise with k, so the k whose interval holds p are one run k_lo..k_hi and the sum is
    binom.cdf(k_hi) − binom.cdf(k_lo − 1) (the same sum; `test_the_cdf_form_is_the_sum` checks it)."""
    assert np.all(np.diff(lo) > 0) and np.all(np.diff(hi) > 0)
    k_hi = np.searchsorted(lo, p, side="right") - 1
    k_lo = np.searchsorted(hi, p, side="left")
    return stats.binom.cdf(k_hi, n, p) - stats.binom.cdf(k_lo - 1, n, p)


def wilson(n: int) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = proportion_confint(np.arange(n + 1), n, alpha=0.05, method="wilson")
    return np.asarray(lo), np.asarray(hi)


def test_rate_interval_known_values():
    # Clopper–Pearson by hand: at 0/n the upper end solves (1 − p)^n = 0.025, at n/n the lower one p^n = 0.025.
    assert rate_interval(0, 12) == pytest.approx((0.0, 1 - 0.025 ** (1 / 12)), abs=1e-12)
    assert rate_interval(10, 10) == pytest.approx((0.025 ** (1 / 10), 1.0), abs=1e-12)
    # 3/4: the upper end solves p^4 = 0.975 (Beta(4, 1)), the lower one the Beta(3, 2) law's 2.5 % point.
    lo, hi = rate_interval(3, 4)
    assert hi == pytest.approx(0.975**0.25, abs=1e-12)
    assert 4 * lo**3 - 3 * lo**4 == pytest.approx(0.025, abs=1e-12)
    assert rate_interval(8, 10) == pytest.approx((0.4439, 0.9748), abs=1e-4)  # the textbook 8/10
    assert rate_interval(0, 0) is None and rate_ci95(0, 0) is None
    assert rate_ci95(8, 10) == pytest.approx([0.4439, 0.9748], abs=1e-4)
    lo, hi = rate_interval(np.arange(11), 10)  # one interval per count, as arrays
    assert (lo[8], hi[8]) == pytest.approx(rate_interval(8, 10))


def test_the_cdf_form_is_the_sum():
    for n in (5, 10, 50, 200, 1000):
        lo, hi = rate_interval(np.arange(n + 1), n)
        k = np.arange(n + 1)[:, None]
        direct = (stats.binom.pmf(k, n, GRID) * ((lo[:, None] <= GRID) & (GRID <= hi[:, None]))).sum(axis=0)
        assert np.abs(direct - coverage(lo, hi, n, GRID)).max() < 1e-12


def test_the_rate_interval_covers_95_percent_at_every_rate_and_wilson_does_not():
    """Every n from 5 to 1,000 and every rate of the grid: exact coverage ≥ 0.95. Wilson's, on the same
    enumeration, falls to 0.911 at n = 50, rate 0.99: the test tells the two apart."""
    worst = 1.0
    for n in range(5, 1001):
        lo, hi = rate_interval(np.arange(n + 1), n)
        worst = min(worst, float(coverage(lo, hi, n, GRID).min()))
    assert worst >= 0.95 - 1e-9
    assert worst < 0.951  # attained: the interval is not wider than it needs to be somewhere
    at = {
        (n, p): float(coverage(*wilson(n), n, np.array([p]))[0])
        for n, p in ((50, 0.99), (50, 0.98), (10, 0.99))
    }
    assert at[(50, 0.99)] < 0.93
    assert at == pytest.approx({(50, 0.99): 0.911, (50, 0.98): 0.922, (10, 0.99): 0.904}, abs=1e-3)
    assert float(coverage(*rate_interval(np.arange(51), 50), 50, np.array([0.99]))[0]) >= 0.95


@pytest.mark.parametrize(
    ("table", "published", "decimals"),
    [
        # Newcombe (1998), Statistics in Medicine 17:2635, its method 10 on its worked example (as the R package
        # ratesci's tests reproduce it): 20 pairs succeed under both, 12 under the first only, 2 under the second only,
        # 16 under neither.
        ((20, 12, 2, 16), (0.0562, 0.3292), 4),
        # Fagerland, Lydersen & Laake (2014), Statistics in Medicine 33:2850: airway hyper-responsiveness before and
        # after stem cell transplantation (Bentur et al. 2009), Newcombe's interval.
        ((1, 1, 7, 12), (-0.507, -0.026), 3),
        # Fagerland, Lydersen & Laake's book (Statistical Analysis of Contingency Tables, chapter 8, as its R package
        # contingencytables tests it): complete response before and after consolidation therapy (Cavo et al. 2012).
        ((59, 6, 16, 80), (-0.1186, -0.0046), 4),
        # Tang et al. (2010), their worked example, as ratesci's tests reproduce it.
        ((8, 3, 1, 2), (-0.1574, 0.4136), 4),
    ],
)
def test_the_paired_difference_interval_matches_published_examples(table, published, decimals):
    assert paired_difference_interval(*table) == pytest.approx(published, abs=0.5 * 10**-decimals)


def test_the_paired_difference_interval_by_hand_and_at_its_edges():
    z = stats.norm.isf(0.025)

    def wilson_at(k: int, n: int) -> tuple[float, float]:
        q, d = k / n, 1 + z * z / n
        centre, half = (q + z * z / (2 * n)) / d, z * np.sqrt(q * (1 - q) / n + z * z / (4 * n * n)) / d
        return centre - half, centre + half

    # 1 first only, 3 second only: φ = −3/√9 = −1, so the ends are the Wilson limits' differences.
    (l1, u1), (l2, u2) = wilson_at(1, 4), wilson_at(3, 4)
    assert paired_difference_interval(0, 1, 3, 0) == pytest.approx((l1 - u2, u1 - l2), abs=1e-12)
    assert paired_difference_ci95(np.array([0, 0, 0, 1]), np.array([1, 1, 1, 0])) == pytest.approx(
        [l1 - u2, u1 - l2], abs=1e-12
    )
    # Every pair succeeds on both sides (a policy at the ceiling): centred on 0, as wide as 1 minus n/n's lower end.
    lo, hi = paired_difference_interval(10, 0, 0, 0)
    assert (lo, hi) == pytest.approx((-(1 - wilson_at(10, 10)[0]), 1 - wilson_at(10, 10)[0]), abs=1e-12)
    assert paired_difference_interval(0, 0, 0, 0) is None and paired_difference_ci95([], []) is None
    lo, hi = paired_difference_interval(
        np.array([20, 1]), np.array([12, 1]), np.array([2, 7]), np.array([16, 12])
    )
    assert (lo[1], hi[1]) == pytest.approx(paired_difference_interval(1, 1, 7, 12))


def _tables(n: int) -> tuple[np.ndarray, ...]:
    """Every paired 2 × 2 table of n pairs: (both, first only, second only, neither)."""
    a, b, c = np.meshgrid(np.arange(n + 1), np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = a + b + c <= n
    a, b, c = a[keep], b[keep], c[keep]
    return a, b, c, n - a - b - c


RATES = (0.5, 0.7, 0.9, 0.95, 0.98, 0.99, 1.0)


@pytest.mark.parametrize("n", [5, 10, 30])
def test_the_paired_difference_interval_covers_nominally(n):
    """Exact coverage over every table of n pairs (the limit of simulating them), value and control success rates
    each in RATES and the pairs' correlation 0, 0.3, 0.6 or 0.9 (the shared seed makes it positive): never below
    0.935, 0.95 or more on average. Newcombe's method 10 is not exact; these are its measured numbers."""
    a, b, c, d = _tables(n)
    lo, hi = paired_difference_interval(a, b, c, d)
    counts = np.stack([a, b, c, d], axis=1)
    covered = []
    for p1 in RATES:
        for p2 in RATES:
            for rho in (0.0, 0.3, 0.6, 0.9):
                both = p1 * p2 + rho * np.sqrt(p1 * (1 - p1) * p2 * (1 - p2))
                cells = np.array([both, p1 - both, p2 - both, 1 - p1 - p2 + both])
                if cells.min() < -1e-12:
                    continue  # no joint law has these margins and this correlation
                pmf = stats.multinomial.pmf(counts, n, np.clip(cells, 0, 1))
                covered.append(pmf[(lo <= p1 - p2) & (p1 - p2 <= hi)].sum())
    assert min(covered) >= 0.935
    assert np.mean(covered) >= 0.95


def test_delta_control_ci95_covers_the_true_difference_by_simulation():
    """Through `control_deltas` as metrics.json computes it: a value at success 0.9 against a control arm at 0.98,
    paired by a shared latent seed per (context, repeat), 4 contexts × 10 repeats; 400 simulated splits."""
    rng = np.random.default_rng(0)
    pairs = pd.MultiIndex.from_product(
        [[f"c{i}" for i in range(4)], range(10)], names=["context_id", "repeat"]
    )
    p_value, p_control = 0.9, 0.98
    hits = []
    for _ in range(400):
        u = rng.random(len(pairs))  # the seed's difficulty, shared by the two episodes of a pair
        noise = rng.random(len(pairs)) < 0.2  # a fifth of the value's episodes draw their own
        value = np.where(noise, rng.random(len(pairs)), u) < p_value
        control = u < p_control
        frame = pairs.to_frame(index=False)
        base = frame.assign(success=control.astype(int))
        rows = frame.assign(value="blue", success=value.astype(int))
        lo, hi = control_deltas(base, rows)["blue"]["delta_control_ci95"]
        hits.append(lo <= p_value - p_control <= hi)
    assert np.mean(hits) >= 0.92  # Monte Carlo SE ≈ 0.011 at 0.95
