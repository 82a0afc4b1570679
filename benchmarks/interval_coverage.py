"""Exact coverage of the success-rate intervals, Wilson's against the Clopper–Pearson interval metrics.json reports
(`sr_ci95`, `sr_control_ci95`, the context and leaderboard rates, the plots' error bars), and of the paired interval
of `delta_control_ci95` (Newcombe's hybrid score), printed as the markdown tables of docs/statistics.md ("Intervals").

    python -m benchmarks.interval_coverage [--sizes=5,10,50,200,1000] [--rates=0.5,0.9,0.95,0.98,0.99] [--pairs=5,10,30]

No simulation: the coverage at a true rate p over n episodes is Σ_k binom.pmf(k, n, p)·[lo_k ≤ p ≤ hi_k], summed over
every count k (both ends rise with k, so it is a difference of two binomial cdfs); "least" is the smallest over every
rate 0.001, 0.002, …, 0.999 and every 0.0001 over 0.95–0.999. The paired interval's coverage sums the multinomial law
over every table of n pairs, for value and control rates in {0.5, 0.7, 0.9, 0.95, 0.98, 0.99, 1} and the pairs'
correlation in {0, 0.3, 0.6, 0.9}.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from statsmodels.stats.proportion import proportion_confint

from roboview.eval.statistics.tables import paired_difference_interval, rate_interval
from roboview.pipelines._cli import cli_main

GRID = np.unique(np.round(np.concatenate([np.arange(1, 1000) / 1000, np.arange(9500, 9991) / 10000]), 10))
PAIRED_RATES = (0.5, 0.7, 0.9, 0.95, 0.98, 0.99, 1.0)
CORRELATIONS = (0.0, 0.3, 0.6, 0.9)


@dataclass
class CoverageConfig:
    # Episodes behind a rate: the table's rows.
    sizes: list[int] = field(default_factory=lambda: [5, 10, 50, 200, 1000])
    # True success rates: the table's columns.
    rates: list[float] = field(default_factory=lambda: [0.5, 0.9, 0.95, 0.98, 0.99])
    # Pairs (context, repeat) behind a value's delta_control: the paired table's rows.
    pairs: list[int] = field(default_factory=lambda: [5, 10, 30])

    def __post_init__(self) -> None:
        if not self.sizes or min(self.sizes) < 1 or not self.pairs or min(self.pairs) < 1:
            raise ValueError(f"--sizes={self.sizes} and --pairs={self.pairs} must be positive counts")
        if not self.rates or not all(0.0 < p < 1.0 for p in self.rates):
            raise ValueError(f"--rates={self.rates} must lie in (0, 1)")


def coverage(lo: np.ndarray, hi: np.ndarray, n: int, p: np.ndarray) -> np.ndarray:
    """Exact coverage at each rate p of the intervals [lo_k, hi_k], k = 0..n (ends rising with k)."""
    k_hi = np.searchsorted(lo, p, side="right") - 1
    k_lo = np.searchsorted(hi, p, side="left")
    return stats.binom.cdf(k_hi, n, p) - stats.binom.cdf(k_lo - 1, n, p)


def wilson(n: int) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = proportion_confint(np.arange(n + 1), n, alpha=0.05, method="wilson")
    return np.asarray(lo), np.asarray(hi)


def paired_coverage(n: int) -> np.ndarray:
    """Exact coverage of `paired_difference_interval` over every table of n pairs, at each (value rate, control
    rate, correlation) a joint law allows."""
    a, b, c = np.meshgrid(*[np.arange(n + 1)] * 3, indexing="ij")
    keep = a + b + c <= n
    a, b, c = a[keep], b[keep], c[keep]
    d = n - a - b - c
    lo, hi = paired_difference_interval(a, b, c, d)
    counts = np.stack([a, b, c, d], axis=1)
    out = []
    for p1 in PAIRED_RATES:
        for p2 in PAIRED_RATES:
            for rho in CORRELATIONS:
                both = p1 * p2 + rho * np.sqrt(p1 * (1 - p1) * p2 * (1 - p2))
                cells = np.array([both, p1 - both, p2 - both, 1 - p1 - p2 + both])
                if cells.min() >= -1e-12:
                    pmf = stats.multinomial.pmf(counts, n, np.clip(cells, 0, 1))
                    out.append(pmf[(lo <= p1 - p2) & (p1 - p2 <= hi)].sum())
    return np.array(out)


def run(cfg: CoverageConfig) -> None:
    rates = np.array(cfg.rates)
    print("Exact coverage of the 95 % success-rate interval, Wilson / Clopper–Pearson:")
    print()
    print("| n | " + " | ".join(f"p = {p:g}" for p in rates) + " | least over p |")
    print("|---|" + "---|" * (len(rates) + 1))
    for n in cfg.sizes:
        w, cp = wilson(n), rate_interval(np.arange(n + 1), n)
        at_w, at_cp = coverage(*w, n, rates), coverage(*cp, n, rates)
        least_w, least_cp = coverage(*w, n, GRID).min(), coverage(*cp, n, GRID).min()
        cells = [f"{x:.3f} / {y:.3f}" for x, y in zip(at_w, at_cp)]
        print(f"| {n} | " + " | ".join(cells) + f" | {least_w:.3f} / {least_cp:.3f} |", flush=True)
    print()
    print("Exact coverage of delta_control_ci95 (Newcombe's paired interval) over value and control rates in")
    print(
        f"{{{', '.join(f'{p:g}' for p in PAIRED_RATES)}}} and correlations {{{', '.join(map(str, CORRELATIONS))}}}:"
    )
    print()
    print("| pairs | least | mean | share below 0.95 |")
    print("|---|---|---|---|")
    for n in cfg.pairs:
        cov = paired_coverage(n)
        print(f"| {n} | {cov.min():.3f} | {cov.mean():.3f} | {np.mean(cov < 0.95):.3f} |", flush=True)


def main(args: list[str] | None = None) -> None:
    cli_main(CoverageConfig, run, args=args)


if __name__ == "__main__":
    main()
