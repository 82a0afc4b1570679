"""Adaptive evaluation: run repeats in rounds and stop a split as soon as its answer is clear.

A split is a table of cells (value × context); a *round* runs one more repeat of every cell, and after each
round from `min_rounds` to `max_repeats` (the planned looks) the evaluator asks "does success depend on the
value?" with the split's own statistic, the likelihood ratio of the binomial GLM `value + context` against
`context` (`roboview.eval.statistics.batch_glm.value_lrt`, the statistic `significance.factor_lrt` computes).
Looking after every round would inflate the error rate of a fixed-n test; a **group-sequential design** spends it
instead (Jennison & Turnbull, *Group Sequential Methods*, ch. 7 and 15: error spending):

- **efficacy** (`bias`): the statistic reaches c_k, set so that under "no bias" crossing first at look k has
  probability α·((k/K)^ρ − ((k−1)/K)^ρ) (an error-spending function of the power family; ρ = 1 spends evenly and
  stops earliest under a strong bias). Over all K looks the type-I error is α.
- **futility** (`no_bias`, binding): the statistic is below f_k, under which a split with a bias of logit SD τ
  falls first at look k with probability β·((k/K)^ρ − ((k−1)/K)^ρ), β = 1 − `power`; futility costs at most β of
  the power against τ. The efficacy boundaries count on it: a split stopped for futility is never run further
  (the runner stops it, and verify recomputes the stop from its rows).
- `max_repeats`: the last look passed without crossing either boundary.

**The boundaries are calibrated on the design's own look sequence.** With a few episodes per cell the χ² law of
the statistic is far off (on 9 values × 4 contexts a χ²-calibrated look rejects 12 % of null splits at a nominal
5 %), and how strongly successive looks are correlated depends on the table. So `boundaries` simulates PATHS whole
splits of the design's shape and success rates, round by round up to `max_repeats`, once under "no bias" and once
with value effects ~ N(0, τ²), computes the statistic at every look of every path (`value_lrt` fits all paths at
once), and sets each c_k and f_k by the spending rule above on those paths. Boundaries depend on the shape (values,
contexts), the contexts' success rates (`calibration_key`: their mean logit and their spread) and the design;
they are computed once and kept in memory and in RoboView's cache folder (`cache_dir("adaptive")`).

The looks are planned (every round up to `max_repeats`): the guarantee covers them, not rounds beyond.
Why not an e-process (valid with no plan at all)? A running-MLE likelihood ratio, simulated on the paper's
camera_pose design (21 values × 11 contexts, SR 0.7, τ = 0.6), needed 5.4 rounds on average for power 0.88
where the fixed LRT needs 2: it pays to learn 21 effects before it gains evidence. The group-sequential LRT
keeps the fixed test's efficiency and stops early where the answer is clear.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats
from scipy.special import expit

from roboview.core.files import cache_dir
from roboview.eval.statistics.batch_glm import value_lrt

STOP_REASONS = ("bias", "no_bias", "max_repeats")
PATHS = 4000  # simulated look sequences behind each boundary, under "no bias" and under the τ bias each
LOGIT_GRID = 0.25  # boundaries are calibrated at the contexts' mean logit success rate, rounded to this step
LOGIT_LIMIT = 3.0  # ... and clipped to ±this (SR 4.7 % – 95.3 %)
SPREAD_GRID = 0.5  # ... and at the SD of the contexts' logits, rounded to this step
SPREAD_LIMIT = 2.0  # ... and at most this
LOGIT_CAP = 4.6  # no simulated context beyond ±this logit (SR 1 % – 99 %)
CALIBRATION = 6  # version of the calibration: cached boundaries of another version are not read


@dataclass(frozen=True)
class Design:
    alpha: float = 0.05
    # Bias of interest: logit SD of the value effects (as roboview.pipelines.plan), and the power kept against it.
    tau: float = 0.3
    power: float = 0.8
    max_repeats: int = 10
    # First look after this many rounds.
    min_rounds: int = 1
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


def grid(n_values: int, n_contexts: int) -> tuple[np.ndarray, np.ndarray]:
    """Value and context codes of a split's cells, one per (value, context)."""
    return np.repeat(np.arange(n_values), n_contexts), np.tile(np.arange(n_contexts), n_values)


def calibration_key(k_context: np.ndarray, n_context: np.ndarray) -> tuple[float, float]:
    """(centre, spread) of the contexts' success rates a split's boundaries are calibrated at, from each context's
    successes and episodes: the mean of their logits, on a grid of LOGIT_GRID within ±LOGIT_LIMIT, and their SD
    beyond sampling noise (method of moments: the logits' variance less the mean of 1 / (n·p·(1 − p))), on a grid of
    SPREAD_GRID up to SPREAD_LIMIT. Contexts at different rates make sparse cells where a pooled rate would not."""
    p = (np.asarray(k_context, float) + 0.5) / (np.asarray(n_context, float) + 1)
    logit = np.log(p / (1 - p))
    centre = float(np.clip(round(logit.mean() / LOGIT_GRID) * LOGIT_GRID, -LOGIT_LIMIT, LOGIT_LIMIT))
    between = (
        logit.var(ddof=1) - np.mean(1 / ((np.asarray(n_context) + 1) * p * (1 - p))) if len(p) > 1 else 0.0
    )
    spread = min(round(math.sqrt(max(between, 0.0)) / SPREAD_GRID) * SPREAD_GRID, SPREAD_LIMIT)
    return centre, float(spread)


def context_rates(n_contexts: int, centre: float, spread: float) -> np.ndarray:
    """Success rates of `n_contexts` contexts whose logits have mean `centre` and SD `spread`, spaced as normal
    quantiles: the contexts a calibration simulates."""
    z = stats.norm.ppf((np.arange(n_contexts) + 0.5) / n_contexts)
    z = z / z.std() if n_contexts > 1 and spread > 0 else np.zeros(n_contexts)
    return expit(np.clip(centre + spread * z, -LOGIT_CAP, LOGIT_CAP))


def outcomes(
    rng: np.random.Generator,
    paths: int,
    rounds: int,
    n_values: int,
    n_contexts: int,
    sr: float | Sequence[float],
    tau: float,
) -> np.ndarray:
    """(paths, rounds, cells) episode outcomes of simulated splits whose values have logit effects ~ N(0, τ²)
    (one draw per path; τ = 0: no bias) around a success rate `sr`, one for all contexts or one per context."""
    value, context = grid(n_values, n_contexts)
    base = np.broadcast_to(np.asarray(sr, float), (n_contexts,))
    effects = rng.normal(0.0, tau, (paths, n_values)) if tau > 0 else np.zeros((paths, n_values))
    p = expit(np.log(base / (1 - base))[context] + effects[:, value])
    return rng.random((paths, rounds, len(value))) < p[:, None, :]


def look_statistics(x: np.ndarray, n_values: int, n_contexts: int, looks: list[int]) -> np.ndarray:
    """(paths, looks) LRT of each simulated split at each look (`x` from `outcomes`)."""
    at, every = live_statistics(x, n_values, n_contexts, looks), np.ones(len(x), bool)
    return np.stack([at(i, every) for i in range(len(looks))], axis=1)


def live_statistics(x: np.ndarray, n_values: int, n_contexts: int, looks: list[int]) -> Callable:
    """`look_statistics` on demand: `at(i, rows)` is the LRT at look i of the paths where `rows` is True (NaN for
    the others), so a calibration fits only the splits still running at each look."""
    value, context = grid(n_values, n_contexts)
    total = x.cumsum(axis=1, dtype=np.int32)

    def at(i: int, rows: np.ndarray) -> np.ndarray:
        out = np.full(len(x), np.nan)
        out[rows] = value_lrt(total[rows, looks[i] - 1], looks[i], value, context)
        return out

    return at


@functools.lru_cache(maxsize=128)
def boundaries(
    n_values: int, n_contexts: int, centre: float, spread: float, design: Design
) -> tuple[np.ndarray, np.ndarray]:
    """(efficacy c_k, futility f_k) on the statistic at each planned look, calibrated on the design's own look
    sequence: PATHS simulated splits of this shape, contexts at `context_rates(centre, spread)`, under "no bias"
    and under the τ bias. Kept in RoboView's cache folder, so a resumed run or a verify computes them once."""
    key = json.dumps([CALIBRATION, PATHS, n_values, n_contexts, centre, spread, asdict(design)])
    path = cache_dir("adaptive") / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.json"
    try:
        stored = json.loads(path.read_text())
        return np.array(stored["efficacy"]), np.array(stored["futility"])
    except (OSError, ValueError, KeyError):
        pass
    rng = np.random.default_rng(0)
    sr = context_rates(n_contexts, centre, spread)
    args = (n_values, n_contexts, design.looks)
    null = live_statistics(outcomes(rng, PATHS, design.max_repeats, n_values, n_contexts, sr, 0.0), *args)
    biased = live_statistics(
        outcomes(rng, PATHS, design.max_repeats, n_values, n_contexts, sr, design.tau), *args
    )
    c, f = spend(null, biased, design, PATHS)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"key": json.loads(key), "efficacy": c.tolist(), "futility": f.tolist()}))
        tmp.replace(path)
    except OSError:  # a read-only cache costs the calibration again next time, nothing else
        pass
    return c, f


def spend(null: Callable, biased: Callable, design: Design, paths: int) -> tuple[np.ndarray, np.ndarray]:
    """Boundaries from simulated look statistics (`live_statistics` of `paths` splits each): c_k lets at most
    α·(s_k − s_{k−1}) of the null paths cross first at look k; f_k stops at most (1 − power)·(s_k − s_{k−1}) of
    the τ-biased paths there. A look where futility would stop every τ-biased split still running is the last: it spends the α left, every split
    stops there, and later looks get c = f = ∞ (a split reaching one stops for `no_bias`).

    Futility is binding: a null path that stopped for futility no longer counts towards later crossings, so the
    efficacy boundaries spend the whole α (with non-binding futility the type-I error of a design that stops
    most null splits early for futility fell to 0.02 on the 21 × 11 shape)."""
    looks = len(design.looks)
    alive0, alive1 = np.ones(paths, bool), np.ones(paths, bool)
    c, f = np.empty(looks), np.empty(looks)
    crossed = 0
    for i in range(looks):
        if not alive0.any() and i:  # every split stopped at an earlier look: none may continue to this one
            c[i] = f[i] = np.inf
            continue
        at0, at1 = null(i, alive0), biased(i, alive1)  # NaN for the splits already stopped
        live = np.sort(at0[alive0])[::-1]
        live1 = np.sort(at1[alive1])
        stopped = int(math.floor((1 - design.power) * (design.spent(i + 1) - design.spent(i)) * paths))
        c[i] = _above(live, int(math.floor(design.alpha * design.spent(i + 1) * paths)) - crossed)
        futility = live1[stopped] if stopped < len(live1) else np.inf
        if i + 1 == looks or futility >= c[i]:
            # Every split stops here (the τ-biased ones still running are all above the efficacy boundary, or
            # few enough for futility to take them all): this look spends all the α left.
            c[i] = _above(live, int(math.floor(design.alpha * paths)) - crossed)
            futility = c[i]
        f[i] = futility
        crossed += int(np.sum(alive0 & (at0 >= c[i])))
        alive0 &= (at0 < c[i]) & (at0 >= f[i])
        alive1 &= (at1 < c[i]) & (at1 >= f[i])
    return c, f


def _above(descending: np.ndarray, allowed: int) -> float:
    """The boundary that at most `allowed` of these statistics (sorted, largest first) reach: just above the
    (allowed + 1)-th largest, so ties cannot overspend; ∞ when none may."""
    if allowed < 0:
        return np.inf
    return float(descending[allowed] * (1 + 1e-7) + 1e-9) if allowed < len(descending) else 0.0


def _stop(statistic: float, efficacy: float, futility: float, last: bool) -> str | None:
    if statistic >= efficacy:
        return "bias"
    if last:
        return "max_repeats"
    return "no_bias" if statistic < futility else None


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
    statistic = float(value_lrt(k, n, value, context)[0])
    n_contexts = int(context.max() + 1)
    centre, spread = calibration_key(
        np.bincount(context, weights=k, minlength=n_contexts),
        np.bincount(context, weights=n, minlength=n_contexts),
    )
    c, f = boundaries(int(value.max() + 1), n_contexts, centre, spread, design)
    i = design.looks.index(rounds)
    stop = _stop(statistic, c[i], f[i], rounds == design.max_repeats)
    finite = [float(x) if np.isfinite(x) else None for x in (c[i], f[i])]
    return Decision(rounds, statistic, *finite, stop)


def simulate(
    n_values: int,
    n_contexts: int,
    sr: float | Sequence[float],
    tau: float,
    design: Design,
    sims: int,
    seed: int = 0,
) -> dict[str, float]:
    """Adaptive runs of simulated splits with a known bias of logit SD `tau` (0: none) around `sr` (one rate, or
    one per context): how often each stop happens, mean rounds and episodes. The tables are binomial draws; the
    statistic and the boundaries are the ones `decide` uses, looked at after every planned round."""
    x = outcomes(np.random.default_rng(seed), sims, design.max_repeats, n_values, n_contexts, sr, tau)
    statistic = look_statistics(x, n_values, n_contexts, design.looks)
    # Successes per context at each look: (paths, looks, contexts).
    cum = x.cumsum(axis=1, dtype=np.int32)[:, [look - 1 for look in design.looks]]
    successes = cum.reshape(sims, len(design.looks), n_values, n_contexts).sum(axis=2)
    rounds = np.full(sims, design.max_repeats)
    stops = np.full(sims, "max_repeats", dtype=object)
    for path in range(sims):
        for i, look in enumerate(design.looks):
            key = calibration_key(successes[path, i], np.full(n_contexts, look * n_values))
            c, f = boundaries(n_values, n_contexts, *key, design)
            stop = _stop(statistic[path, i], c[i], f[i], look == design.max_repeats)
            if stop:
                rounds[path], stops[path] = look, stop
                break
    return {
        "rejection_rate": float(np.mean(stops == "bias")),
        "mean_rounds": float(np.mean(rounds)),
        "mean_episodes": float(np.mean(rounds)) * n_values * n_contexts,
        **{f"stopped_{s}": float(np.mean(stops == s)) for s in STOP_REASONS},
    }


def fixed_power(
    n_values: int, n_contexts: int, sr: float, tau: float, repeats: int, alpha: float, paths: int = PATHS
) -> float:
    """Power of the fixed design with `repeats` repeats against a bias of logit SD τ: the same LRT, its critical
    value the (1 − α) quantile of simulated null splits of this shape and success rate (so neither design is
    helped by the χ² reference, anticonservative on sparse tables)."""
    rng = np.random.default_rng(1)
    args = (n_values, n_contexts, [repeats])
    null = look_statistics(outcomes(rng, paths, repeats, n_values, n_contexts, sr, 0.0), *args)[:, 0]
    biased = look_statistics(outcomes(rng, paths, repeats, n_values, n_contexts, sr, tau), *args)[:, 0]
    critical = _above(np.sort(null)[::-1], int(math.floor(alpha * paths)))
    return float(np.mean(biased >= critical))


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
    from pathlib import Path

    path = Path(folder) / RECORD_FILE
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"design": asdict(design), "splits": records}, indent=2))
    tmp.replace(path)


def read_record(folder) -> dict | None:
    from pathlib import Path

    path = Path(folder) / RECORD_FILE
    return json.loads(path.read_text()) if path.is_file() else None
