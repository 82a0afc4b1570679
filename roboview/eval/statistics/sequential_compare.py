"""Adaptive paired comparison of two policies: run repeats in rounds on the same benchmark, and stop as soon as the
difference is decided.

Two policies evaluated on the same (instance, repeat) pairs share each pair's seed and scene (common random
numbers), so they separate fast when they differ: only the *discordant* pairs (one succeeds, the other fails)
carry evidence about the difference in success rate, and McNemar's test uses exactly those. A round is one more
repeat of every instance by both policies; after round k (a *look*) the comparison asks:

- **SR**: McNemar's test on every pair of rounds 1…k (the discordant pairs and how many of them each policy won),
  pooled over the splits and per split.
- **cv_excess** (per single-factor split): the paired permutation test of the difference in cv_excess
  (`compare_pair`, policy labels swapped within each instance).

Looking after every round would inflate a fixed-n test's error rate. Each look instead spends
α·((k/K)^ρ − ((k−1)/K)^ρ) of the type-I error (K = `max_repeats`, the planned looks; ρ = 1 spends evenly):

- **SR** crosses an exact group-sequential boundary (`sign_boundaries`): given the discordant pairs seen by each
  look, the pairs B won follow a binomial random walk under "equal SR", whose law across looks is computed exactly,
  so the looks spend α jointly, with no union bound and no approximation.
- **cv_excess** has no such closed form: each look's permutation p-value is tested against the error it spends, and
  by the union bound the chance of a false verdict over all K looks is at most α whatever the dependence between
  looks.

The suite checks by simulation that two equal policies are declared different in at most α of comparisons stopped
at the first crossing.

Verdicts: `A better` / `B better` (SR), `A less biased` / `B less biased` (cv_excess), `not separated` (every
planned look passed without a crossing), or `undecided` with `needs`: the rounds after which the crossing would
come if the discordant pairs kept their rate and split (against the same exact boundaries), or None when no
difference is seen at all.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from roboview.eval.statistics.compare import compare_pair
from roboview.eval.statistics.significance import paired_success_test
from roboview.eval.statistics.tables import MetricsConfig

SR_VERDICTS = ("A better", "B better")
CV_VERDICTS = ("A less biased", "B less biased")


@dataclass(frozen=True)
class CompareDesign:
    """The planned looks of an adaptive comparison and the error they may spend."""

    # Type-I error of a "better" / "less biased" verdict, over every look.
    alpha: float = 0.05
    # The planned looks: one after each round, 1 … max_repeats.
    max_repeats: int = 10
    # Shape of the error spending: α·(k/K)^ρ spent by look k (ρ > 1 keeps more for the late looks).
    rho: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise ValueError(f"--alpha={self.alpha} must lie in (0, 1)")
        if self.max_repeats < 1:
            raise ValueError(f"--max_repeats={self.max_repeats} must be ≥ 1 (the planned looks)")
        if not self.rho > 0:
            raise ValueError(f"--rho={self.rho} must be > 0")

    def spent(self, look: int) -> float:
        """The type-I error look `look` (1-based) may spend."""
        k = self.max_repeats
        return self.alpha * ((look / k) ** self.rho - ((look - 1) / k) ** self.rho)


def sign_boundaries(discordant: list[int], design: CompareDesign) -> list[int]:
    """Exact group-sequential boundaries of McNemar's test: b_k on |2·W_k − D_k| at each look, where D_k is the number
    of discordant pairs by look k and W_k how many of them B won.

    Under "equal SR", given the discordant counts, each discordant pair is B's with probability ½ independently, so
    W_1, W_2, … is a binomial random walk observed at D_1 ≤ D_2 ≤ …. Its law is propagated exactly (a convolution per
    look); b_k is the smallest boundary that the walks still running cross at look k with probability at most
    α·((k/K)^ρ − ((k−1)/K)^ρ). Every b_j depends only on D_1 … D_j, so each look recomputes the same earlier
    boundaries, and the chance of any false verdict over the K looks is at most α given the discordant counts,
    hence overall."""
    alive = np.ones(1)
    bounds, before = [], 0
    for k, d in enumerate(discordant, start=1):
        alive = np.convolve(alive, stats.binom.pmf(np.arange(d - before + 1), d - before, 0.5))
        before = d
        distance = np.abs(2 * np.arange(d + 1) - d)
        # P(|2W − D| ≥ b) among the running walks, for every candidate b = D, D − 1, …, 0.
        tail = np.cumsum(np.bincount(distance, weights=alive, minlength=d + 1)[::-1])[::-1]
        allowed = np.flatnonzero(tail <= design.spent(k) * (1 + 1e-9))
        bound = int(allowed[0]) if len(allowed) else d + 1
        bounds.append(bound)
        alive = np.where(distance >= bound, 0.0, alive)
    return bounds


def sr_looks(a: np.ndarray, b: np.ndarray, design: CompareDesign) -> dict[str, Any]:
    """The sequential SR comparison of paired outcomes `a`, `b` ((pairs per round, rounds) bool arrays, column k the
    round-k outcome of each pair): the verdict, the look it was reached at, and each look's McNemar p-value."""
    rounds = min(a.shape[1], design.max_repeats)
    wins_b = np.cumsum(np.sum(b & ~a, axis=0))[:rounds]
    discordant = np.cumsum(np.sum(a != b, axis=0))[:rounds]
    bounds = sign_boundaries([int(d) for d in discordant], design)
    looks = []
    for k in range(1, rounds + 1):
        looks.append(paired_success_test(a[:, :k].ravel(), b[:, :k].ravel()))
        if abs(2 * int(wins_b[k - 1]) - int(discordant[k - 1])) >= bounds[k - 1]:
            delta = float(b[:, :k].mean() - a[:, :k].mean())
            return _decided(SR_VERDICTS[delta > 0], k, delta, looks[-1], design, looks)
    delta = float(b[:, :rounds].mean() - a[:, :rounds].mean()) if rounds else 0.0
    return _open(rounds, delta, looks, design) | {
        "needs": rounds_needed(a[:, :rounds], b[:, :rounds], design)
    }


def rounds_needed(a: np.ndarray, b: np.ndarray, design: CompareDesign) -> int | None:
    """Further rounds until the SR crossing, if the discordant pairs kept coming at the rate seen so far and split as
    they have: the first later look j whose exact boundary (`sign_boundaries` over the looks seen and the projected
    ones) the projected |2W_j − D_j| would reach. None when no difference is seen (no discordant pair, or as many
    each way) or none of the planned looks would show it."""
    k = a.shape[1]
    wins_b, wins_a = int(np.sum(b & ~a)), int(np.sum(a & ~b))
    discordant = wins_a + wins_b
    if k == 0 or discordant == 0 or wins_a == wins_b:
        return None
    seen = [int(d) for d in np.cumsum(np.sum(a != b, axis=0))]
    planned = [round(discordant / k * j) for j in range(k + 1, design.max_repeats + 1)]
    bounds = sign_boundaries(seen + planned, design)
    for j, d in enumerate(planned, start=k + 1):
        if abs(2 * round(wins_b / discordant * d) - d) >= bounds[j - 1]:
            return j - k
    return None


def compare_in_rounds(
    episodes: pd.DataFrame, name_a: str, name_b: str, design: CompareDesign, cfg: MetricsConfig
) -> dict[str, Any]:
    """Both policies' episodes (one table, `policy` naming them) → the sequential comparison, pooled over the
    splits (SR) and per split (SR and, for single-factor splits, cv_excess), on the rounds both completed."""
    overall_a, overall_b, splits = [], [], {}
    for split, rows in episodes.groupby("split", sort=True):
        a, b = paired_rounds(rows, name_a, name_b)
        if a.size == 0:
            continue
        overall_a.append(a)
        overall_b.append(b)
        splits[str(split)] = {
            "n_pairs_per_round": int(a.shape[0]),
            "rounds": int(a.shape[1]),
            "sr": sr_looks(a, b, design),
            "cv_excess": cv_looks(rows, name_a, name_b, a.shape[1], design, cfg, str(split)),
        }
    if not splits:
        raise ValueError(
            f"{name_a} and {name_b} share no (instance, repeat) pair: evaluate both on the same benchmark and splits"
        )
    rounds = min(x.shape[1] for x in overall_a)
    a = np.concatenate([x[:, :rounds] for x in overall_a])
    b = np.concatenate([x[:, :rounds] for x in overall_b])
    return {
        "policies": [name_a, name_b],
        "design": {"alpha": design.alpha, "max_repeats": design.max_repeats, "rho": design.rho},
        "overall": {"n_pairs_per_round": int(a.shape[0]), "rounds": rounds, "sr": sr_looks(a, b, design)},
        "splits": splits,
    }


def paired_rounds(rows: pd.DataFrame, name_a: str, name_b: str) -> tuple[np.ndarray, np.ndarray]:
    """(instances, rounds) success arrays of both policies on one split: the instances both ran (say, under two
    different `--eval.limit`s), and the leading rounds 0 … r−1 that every one of them completed for both (a round
    in progress is not looked at)."""
    shared = set(rows.loc[rows["policy"] == name_a, "instance_id"]) & set(
        rows.loc[rows["policy"] == name_b, "instance_id"]
    )
    rows = rows[rows["instance_id"].isin(shared)]
    wide = rows.pivot_table(
        index="instance_id", columns=["policy", "repeat"], values="success", aggfunc="first"
    )
    if name_a not in wide.columns.get_level_values(0) or name_b not in wide.columns.get_level_values(0):
        return np.zeros((0, 0), bool), np.zeros((0, 0), bool)
    a, b = wide[name_a], wide[name_b]
    rounds = 0
    while rounds in a.columns and rounds in b.columns and a[rounds].notna().all() and b[rounds].notna().all():
        rounds += 1
    cols = list(range(rounds))
    return a[cols].to_numpy(bool), b[cols].to_numpy(bool)


def cv_looks(
    rows: pd.DataFrame,
    name_a: str,
    name_b: str,
    rounds: int,
    design: CompareDesign,
    cfg: MetricsConfig,
    split: str,
) -> dict[str, Any] | None:
    """The sequential cv_excess comparison of one single-factor split (None for a factorial one): the paired
    permutation test of each look against the error it spends."""
    if "|" in str(rows["factor"].iloc[0]):
        return None
    looks: list[float | None] = []
    delta = None
    for k in range(1, min(rounds, design.max_repeats) + 1):
        result = compare_pair(rows[rows["repeat"] < k], name_a, name_b, cfg, split)
        p, delta = (None, None) if result is None else (result["p_cv_excess"], result["delta_cv_excess"])
        looks.append(p)
        if p is not None and delta is not None and p <= design.spent(k):
            return _decided(CV_VERDICTS[delta < 0], k, delta, p, design, looks)
    return _open(min(rounds, design.max_repeats), delta, looks, design)


def _decided(verdict: str, look: int, delta: float, p: float, design: CompareDesign, looks: list) -> dict:
    return {
        "verdict": verdict,
        "look": look,
        "delta": delta,
        "p": p,
        "alpha_spent": design.spent(look),
        "p_looks": looks,
    }


def _open(rounds: int, delta: float | None, looks: list, design: CompareDesign) -> dict:
    verdict = "not separated" if rounds >= design.max_repeats else "undecided"
    return {
        "verdict": verdict,
        "look": None,
        "delta": delta,
        "p": looks[-1] if looks else None,
        "p_looks": looks,
    }
