"""Coverage of candidate 95 % intervals for `cv_excess` by simulation against the noise-free CV of the true success
probabilities (docs/statistics.md, "An interval for cv_excess").

    python -m benchmarks.cv_excess_interval [--reps=200] [--boot=200] [--values=9] [--contexts=4] [--sr=0.7]

Each replicate draws a split as `roboview.eval.statistics.simulate.simulate_split` does (value effects of logit SD
τ around SR, n repeats), computes cv_excess as metrics.json does (CV against its within-(context, repeat)
permutation floor), and builds each candidate interval from a parametric bootstrap: tables drawn from the cell
probabilities shrunk toward their context mean so that their own CV is the estimate (s = cv_excess / cv), each
bootstrap table's cv_excess computed the same way. Candidates: `percentile` [q2.5, q97.5]; `basic`
[2θ̂ − q97.5, 2θ̂ − q2.5] clipped at 0; `percentile_0` the percentile interval with its lower end at 0 where the
CV permutation test does not reject at 0.05.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from roboview.eval.statistics.tables import EPSILON, excess
from roboview.pipelines._cli import cli_main

N_PERM = 100


def cv_of(k: np.ndarray, n: int) -> np.ndarray:
    """CV of success counts k (..., V, C) at n repeats: mean over contexts of σ_v / (μ_v + ε)."""
    sr = k / n
    return (sr.std(axis=-2) / (sr.mean(axis=-2) + EPSILON)).mean(axis=-1)


def cv_and_null(outcomes: np.ndarray, rng: np.random.Generator) -> tuple[float, float, float]:
    """cv, cv_null (values shuffled within each (context, repeat)) and the permutation p of cv, for (V, C, n)
    outcomes."""
    n = outcomes.shape[2]
    cv = float(cv_of(outcomes.sum(axis=2), n))
    perm = rng.permuted(np.broadcast_to(outcomes, (N_PERM, *outcomes.shape)), axis=1)
    null = cv_of(perm.sum(axis=3), n)
    return cv, float(null.mean()), float((1 + np.sum(null >= cv - 1e-12)) / (1 + N_PERM))


def interval(outcomes: np.ndarray, boot: int, rng: np.random.Generator) -> dict[str, tuple[float, float]]:
    n = outcomes.shape[2]
    cv, null, p = cv_and_null(outcomes, rng)
    theta = excess(cv, null)
    sr = outcomes.mean(axis=2)  # (V, C)
    mu = sr.mean(axis=0, keepdims=True)
    shrunk = np.clip(mu + (theta / cv if cv > 0 else 0.0) * (sr - mu), 0.0, 1.0)
    stars = []
    for _ in range(boot):
        draw = rng.random((*shrunk.shape, n)) < shrunk[:, :, None]
        c, z, _ = cv_and_null(draw, rng)
        stars.append(excess(c, z))
    lo, hi = np.quantile(stars, [0.025, 0.975])
    return {
        "estimate": (theta, theta),
        "percentile": (float(lo), float(hi)),
        "basic": (max(0.0, 2 * theta - hi), max(0.0, 2 * theta - lo)),
        "percentile_0": (0.0 if p >= 0.05 else float(lo), float(hi)),
    }


def simulate(
    rng, values: int, contexts: int, repeats: int, tau: float, sr: float
) -> tuple[np.ndarray, float]:
    beta = rng.normal(0.0, tau, values)
    p = 1 / (1 + np.exp(-(math.log(sr / (1 - sr)) + beta)))
    truth = float(p.std() / p.mean())  # the same in every context
    outcomes = rng.random((values, contexts, repeats)) < p[:, None, None]
    return outcomes, truth


def coverage(
    reps: int, boot: int, values: int, contexts: int, repeats: int, tau: float, sr: float, seed: int
):
    rng = np.random.default_rng(seed)
    hits: dict[str, int] = {}
    width: dict[str, float] = {}
    for _ in range(reps):
        outcomes, truth = simulate(rng, values, contexts, repeats, tau, sr)
        for name, (lo, hi) in interval(outcomes, boot, rng).items():
            if name == "estimate":
                continue
            hits[name] = hits.get(name, 0) + (lo - 1e-12 <= truth <= hi + 1e-12)
            width[name] = width.get(name, 0.0) + (hi - lo) / reps
    return {k: v / reps for k, v in hits.items()}, width


@dataclass
class IntervalConfig:
    # Simulated splits per (τ, n) cell of the grid.
    reps: int = 200
    # Bootstrap tables behind each interval.
    boot: int = 200
    # Values of the simulated single-factor split.
    values: int = 9
    # Contexts per value.
    contexts: int = 4
    # Mean success rate of the simulated policy.
    sr: float = 0.7

    def __post_init__(self) -> None:
        for name in ("reps", "boot", "values", "contexts"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name}={getattr(self, name)} must be a positive count")
        if not 0.0 < self.sr < 1.0:
            raise ValueError(f"--sr={self.sr} must lie in (0, 1)")


def run(cfg: IntervalConfig) -> None:
    print("| τ | n | percentile | basic | percentile_0 | mean width (percentile) |")
    print("|---|---|---|---|---|---|")
    for tau in (0.0, 0.3, 0.6):
        for n in (2, 5, 10):
            cov, width = coverage(cfg.reps, cfg.boot, cfg.values, cfg.contexts, n, tau, cfg.sr, seed=n)
            print(
                f"| {tau:g} | {n} | {cov['percentile']:.3f} | {cov['basic']:.3f} | {cov['percentile_0']:.3f} | "
                f"{width['percentile']:.3f} |",
                flush=True,
            )


def main(args: list[str] | None = None) -> None:
    cli_main(IntervalConfig, run, args=args)


if __name__ == "__main__":
    main()
