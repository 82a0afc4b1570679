"""Adaptive evaluation: run repeats in rounds and stop a split as soon as its answer is clear.

A split is a table of cells (value × context); a *round* runs one more repeat of every cell, and after each
round from `min_rounds` to `max_repeats` (the planned looks) the evaluator asks "does success depend on the
value?" with the split's own test, the binomial GLM likelihood-ratio test of `value + context` against
`context` (`roboview.eval.statistics.significance.factor_lrt`, χ² reference). Looking after every round would inflate the error rate of
a fixed-n test; a **group-sequential design** spends it instead (Jennison & Turnbull, *Group Sequential
Methods*, ch. 15, χ² tests):

- **efficacy** (`bias`): at look k the test may spend α·((k/K)^ρ − ((k−1)/K)^ρ) of the type-I error (an
  error-spending function of the power family; ρ = 1, the default, spends evenly and stops earliest under a
  strong bias). Where the table is dense (Cochran's rule, as the fixed analysis decides), the LRT is compared
  with a boundary c_k set so that, under "no bias", crossing first at look k has exactly that probability.
  Where it is sparse (few episodes per cell: the usual case in early rounds) the χ² reference is
  anticonservative and looks are less correlated than it assumes, so the look tests the exact
  within-context permutation p-value of the LRT against the error it spends alone; by the union bound such
  looks cost at most what they spend. Over all K looks the type-I error is at most α.
- **futility** (`no_bias`, non-binding): the LRT is below f_k, which a bias of logit SD τ exceeds except with
  probability β·((k/K)^ρ − ((k−1)/K)^ρ), β = 1 − `power`; over all looks at most a share β of τ-biased
  splits stops this way, so futility costs at most β of the power against τ. It never rejects, so it
  cannot raise the type-I error.
- `max_repeats`: the last look passed without crossing either boundary.

The dense-table boundaries (and the futility boundaries) come from the χ² process the LRT follows across
looks: with df = values − 1, LRT_k ≈ ‖W_k‖² / k for a df-dimensional random walk W with N(0, I) steps under "no bias" and N(μ, I) steps under a bias of
per-round non-centrality ‖μ‖² = λ (λ drawn from the τ prior as `roboview.eval.statistics.significance.lrt_power` does). They depend on
the design (values, contexts, success rate) only through df and λ, and are computed by Monte Carlo.

The looks are planned (every round up to `max_repeats`): the guarantee covers them, not rounds beyond.
Why not an e-process (valid with no plan at all)? A running-MLE likelihood ratio, simulated on the paper's
camera_pose design (21 values × 11 contexts, SR 0.7, τ = 0.6), needed 5.4 rounds on average for power 0.88
where the fixed LRT needs 2: it pays to learn 21 effects before it gains evidence. The group-sequential LRT
keeps the fixed test's efficiency and stops early where the answer is clear.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from roboview.eval.statistics.significance import factor_lrt, informative, is_sparse

STOP_REASONS = ("bias", "no_bias", "max_repeats")
PATHS = 20_000  # Monte Carlo paths behind each boundary
PERMUTATION_BATCH = 100  # permuted tables per factor_lrt call in a sparse look


@dataclass(frozen=True)
class Design:
    alpha: float = 0.05
    # Bias of interest: logit SD of the value effects (as roboview.pipelines.plan), and the power kept against it.
    tau: float = 0.3
    power: float = 0.8
    max_repeats: int = 10
    # First look after this many rounds (one round's table is too sparse for the χ² reference).
    min_rounds: int = 2
    # Shape of the error spending: α·(k/K)^ρ spent by look k.
    rho: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise ValueError(f"--eval.alpha={self.alpha} must lie in (0, 1)")
        if not self.tau > 0:
            raise ValueError(
                f"--eval.tau={self.tau} must be > 0 (logit SD of the value effects, as roboview.pipelines.plan)"
            )
        if not 0 < self.power < 1:
            raise ValueError(f"--eval.power={self.power} must lie in (0, 1)")
        if not 1 <= self.min_rounds <= self.max_repeats:
            raise ValueError(
                f"--eval.max_repeats={self.max_repeats} must be ≥ the first look ({self.min_rounds} rounds)"
            )

    @property
    def looks(self) -> list[int]:
        return list(range(self.min_rounds, self.max_repeats + 1))

    def spent(self, k: int) -> float:
        """Share of the error spent by look k (1-based over the planned looks)."""
        return (k / len(self.looks)) ** self.rho


def noncentrality(n_values: int, n_contexts: int, sr: float, tau: float, draws: int) -> np.ndarray:
    """Per-round non-centrality of the LRT under value effects ~ N(0, τ²) (one draw per path)."""
    beta = np.random.default_rng(1).normal(0.0, tau, (draws, n_values))
    logit = math.log(sr / (1 - sr))
    p = 1 / (1 + np.exp(-(logit + beta)))
    w = p * (1 - p)
    return n_contexts * ((w * beta**2).sum(axis=1) - (w * beta).sum(axis=1) ** 2 / w.sum(axis=1))


@functools.lru_cache(maxsize=64)
def boundaries(df: int, n_contexts: int, sr: float, design: Design) -> tuple[np.ndarray, np.ndarray]:
    """(efficacy c_k, futility f_k) for the planned looks, on the LRT statistic."""
    rng = np.random.default_rng(0)
    K = len(design.looks)
    lam = noncentrality(df + 1, n_contexts, float(np.clip(sr, 0.05, 0.95)), design.tau, PATHS)
    mu = np.sqrt(lam)
    w0 = np.zeros((PATHS, df))
    w1 = np.zeros((PATHS, df))
    alive0 = np.ones(PATHS, bool)
    alive1 = np.ones(PATHS, bool)
    c, f = np.empty(K), np.empty(K)
    rounds_done = 0
    for i, look in enumerate(design.looks):
        steps = look - rounds_done
        rounds_done = look
        w0 += rng.normal(0, math.sqrt(steps), (PATHS, df))
        w1 += rng.normal(0, math.sqrt(steps), (PATHS, df))
        w1[:, 0] += mu * steps
        s0 = (w0**2).sum(axis=1) / look
        s1 = (w1**2).sum(axis=1) / look
        a_k = design.alpha * (design.spent(i + 1) - design.spent(i))
        b_k = (1 - design.power) * (design.spent(i + 1) - design.spent(i))
        # c_k: the largest boundary whose crossing by still-running null paths has probability a_k.
        live = np.sort(s0[alive0])[::-1]
        n_cross = int(math.floor(a_k * PATHS))
        c[i] = live[n_cross] if n_cross < len(live) else 0.0
        alive0 &= s0 < c[i]
        # f_k: below it lie a share b_k of the τ-biased paths still running.
        live1 = np.sort(s1[alive1])
        n_fut = int(math.floor(b_k * PATHS))
        f[i] = min(live1[n_fut] if n_fut < len(live1) else c[i], c[i]) if i + 1 < K else c[i]
        alive1 &= (s1 < c[i]) & (s1 >= f[i])
    return c, f


def _sparse(k: np.ndarray, n: np.ndarray, value: np.ndarray, context: np.ndarray) -> bool:
    """Cochran's rule on the context-only fit, as the fixed analysis decides its p-value's reference."""
    keep = informative(k, n, context)
    if not keep.any():
        return False
    p_ctx = np.bincount(context, weights=k) / np.bincount(context, weights=n)
    return is_sparse(n[keep], p_ctx[context][keep])


def permutation_confirms(
    k: np.ndarray,
    n: np.ndarray,
    value: np.ndarray,
    context: np.ndarray,
    observed: float,
    level: float,
    seed: int = 0,
    max_draws: int = 4000,
) -> bool:
    """Whether the within-context permutation p-value of the LRT is ≤ `level`.

    Under "no bias" the successes of a context are exchangeable across its episodes, so a permuted table
    deals each context's successes among its cells at random (a multivariate hypergeometric draw with the
    cells' sizes). The permuted tables go through `factor_lrt`'s own permutation calibration, a batch at a
    time; drawing stops once too many reach the observed statistic for p ≤ `level` to remain possible.
    """
    rng = np.random.default_rng(seed)
    draws = min(max_draws, max(100, int(math.ceil(2 / level))))
    allowed = level * (draws + 1) - 1  # exceedances that still leave (1 + e) / (1 + draws) ≤ level
    members = [np.flatnonzero(context == c) for c in range(int(context.max() + 1))]
    totals = [int(k[m].sum()) for m in members]
    exceed = seen = 0
    while seen < draws:
        batch = min(PERMUTATION_BATCH, draws - seen)
        permuted = np.empty((batch, len(k)))
        for m, total in zip(members, totals):
            permuted[:, m] = rng.multivariate_hypergeometric(n[m].astype(np.int64), total, size=batch)
        test = factor_lrt(k.astype(float), n.astype(float), value, context, permuted)
        if test is None or test.method != "permutation":  # not sparse after all: its χ² p is the answer
            return test is not None and test.p_value <= level
        exceed += round(test.p_value * (batch + 1)) - 1  # p = (1 + exceedances) / (1 + batch)
        seen += batch
        if exceed > allowed:
            return False
    return True


@dataclass(frozen=True)
class Decision:
    rounds: int
    statistic: float | None
    efficacy: float | None
    futility: float | None
    stopped: str | None  # None: run another round

    def record(self, episodes: int) -> dict:
        return {
            "rounds": self.rounds,
            "episodes": episodes,
            "stopped": self.stopped,
            "lrt": self.statistic,
            "efficacy_boundary": self.efficacy,
            "futility_boundary": self.futility,
        }


def decide(
    k: np.ndarray, n: np.ndarray, value: np.ndarray, context: np.ndarray, rounds: int, design: Design
) -> Decision:
    """What to do after `rounds` rounds of a split whose cells hold k successes of n episodes."""
    if rounds < design.min_rounds:
        return Decision(rounds, None, None, None, None)
    if rounds not in design.looks:
        return Decision(rounds, None, None, None, "max_repeats")
    test = factor_lrt(k.astype(float), n.astype(float), value, context, None)
    statistic = 0.0 if test is None else test.statistic  # no informative context: no evidence of a bias
    n_values, n_contexts = int(value.max() + 1), int(context.max() + 1)
    sr = float(k.sum() / n.sum())
    c, f = boundaries(n_values - 1, n_contexts, round(sr, 2), design)
    i = design.looks.index(rounds)
    if _sparse(k, n, value, context):
        # Sparse cells: the χ² reference is anticonservative and the looks' statistics are less correlated
        # than the χ² process assumes. Such a look tests the exact within-context permutation p-value against
        # the error it spends alone, α·(s_k − s_{k−1}): by the union bound these looks cost at most what
        # they spend, whatever their correlation. (χ² p above ten times that level cannot cross: not tested.)
        level = design.alpha * (design.spent(i + 1) - design.spent(i))
        crossed = (
            test is not None
            and test.p_value <= 10 * level
            and permutation_confirms(k, n, value, context, statistic, level, seed=rounds)
        )
    else:
        crossed = statistic >= c[i]
    if crossed:
        stop = "bias"
    elif rounds == design.max_repeats:
        stop = "max_repeats"
    elif statistic < f[i]:
        stop = "no_bias"
    else:
        stop = None
    return Decision(rounds, statistic, float(c[i]), float(f[i]), stop)


def simulate(
    n_values: int, n_contexts: int, sr: float, tau: float, design: Design, sims: int, seed: int = 0
) -> dict[str, float]:
    """Adaptive runs of simulated splits with a known bias of logit SD `tau` (0: none), every context at
    `sr`: how often each stop happens, mean rounds and episodes (real binomial tables, the real test)."""
    rng = np.random.default_rng(seed)
    value = np.repeat(np.arange(n_values), n_contexts)
    context = np.tile(np.arange(n_contexts), n_values)
    logit = math.log(sr / (1 - sr))
    rounds, stops = [], []
    for _ in range(sims):
        p = (
            1 / (1 + np.exp(-(logit + rng.normal(0, tau, n_values))))[value]
            if tau > 0
            else np.full(len(value), sr)
        )
        x = rng.random((design.max_repeats, len(value))) < p
        for t in range(1, design.max_repeats + 1):
            decision = decide(x[:t].sum(axis=0), np.full(len(value), t), value, context, t, design)
            if decision.stopped:
                break
        rounds.append(decision.rounds)
        stops.append(decision.stopped)
    stops_a = np.array(stops)
    return {
        "rejection_rate": float(np.mean(stops_a == "bias")),
        "mean_rounds": float(np.mean(rounds)),
        "mean_episodes": float(np.mean(rounds)) * len(value),
        **{f"stopped_{s}": float(np.mean(stops_a == s)) for s in STOP_REASONS},
    }


RECORD_FILE = "adaptive.json"


def decide_split(rows: list[dict], rounds: int, design: Design) -> Decision:
    """The decision after `rounds` rounds from a split's episode rows (every instance × repeats < rounds)."""
    if rounds < design.min_rounds or not rows:
        return Decision(rounds, None, None, None, None)
    import pandas as pd

    frame = pd.DataFrame(rows)
    cells = frame.groupby(["value", "context_id"])["success"].agg(["sum", "size"]).reset_index()
    value = pd.factorize(cells["value"], sort=True)[0]
    context = pd.factorize(cells["context_id"], sort=True)[0]
    if value.max() < 1:  # one value: nothing to compare
        return Decision(rounds, None, None, None, "max_repeats")
    return decide(cells["sum"].to_numpy(), cells["size"].to_numpy(), value, context, rounds, design)


def write_record(folder, design: Design, records: dict[str, dict]) -> None:
    """OUT/adaptive.json: the design and, per split that stopped, when and why (atomic)."""
    import json
    from dataclasses import asdict
    from pathlib import Path

    path = Path(folder) / RECORD_FILE
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"design": asdict(design), "splits": records}, indent=2))
    tmp.replace(path)


def read_record(folder) -> dict | None:
    import json
    from pathlib import Path

    path = Path(folder) / RECORD_FILE
    return json.loads(path.read_text()) if path.is_file() else None
