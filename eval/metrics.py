"""Bias metrics of paper §5.4 made exact (DESIGN.md, "Metrics"), with uncertainty on top.

Everything here is a pure function of an episodes table (one row per episode, DESIGN.md "Episode
record"). Notation: a *cell* is a value v (or a value pair (a, b) in a factorial split) in a
context c; SR(v, c) is the mean success over every episode of the instances in that cell.

- Average Success Rate `sr`: mean success over the split's episodes.
- Conditional CV (CCV): CV(V | c) = σ_v SR(v, c) / (μ_v SR(v, c) + ε), σ population (ddof = 0).
  A context where everything failed has CV = 0 / (0 + ε) = 0.
- Bias Coefficient `cv`: mean over contexts c of CV(V | c); null when every episode failed
  (0/ε would report "no bias" for a policy that never succeeds).
- Factorial split over (A, B): CV(A | b, c) over a; `cv[A]` = mean over (b, c);
  IEC(A; B) = mean over c of σ_b CV(A|b,c) / (μ_b CV(A|b,c) + ε), keyed "A|B"; same for B.

Beyond the paper (why: a CV from 5 repeats is noisy, and readers must see how noisy):

- `sr_ci95`: Wilson score interval over episodes (treats episodes as independent Bernoulli
  trials; it stays defined, as an upper bound, when every episode failed).
- `cv_ci95` / `iec_ci95`: bootstrap that resamples each instance's episodes with replacement.
  Resampling n binary outcomes with k successes is exactly a Binomial(n, k/n) draw, so replicates
  draw success counts directly (1,551 instances × 1,000 replicates: well under a second). The
  interval is the bootstrap's 2.5–97.5 % spread placed around the reported value,
  [CV + q2.5 − q50, CV + q97.5 − q50] clipped at 0: how far the reported CV moves when the
  repeats are rerun. Why not the plain percentile interval: repeat noise adds p(1−p)/n to every
  SR's variance, so CV is biased upward and resampling adds that bias a second time — with 5
  repeats the percentile interval of a realistic table lies wholly above the reported CV.
  `cv_bias` / `iec_bias` (mean replicate − reported value) state that bias instead of hiding it.
  An instance whose repeats all agree contributes no spread: the interval covers repeat noise
  only, not the choice of instances or contexts.
- `p_value`: permutation test of "success depends on the factor". Under the null the value labels
  of episodes are exchangeable within a context (within (b, c) for A in a factorial split), so a
  permutation redistributes the context's successes over its cells: a multivariate
  hypergeometric draw. Statistic: the Bias Coefficient itself. p = (1 + #{CV_perm ≥ CV}) / (1 + n).
  Labels are permuted per episode, not per instance: with one instance per cell, shuffling whole
  instances only reorders the values and leaves CV unchanged.

Output layout (`compute_metrics`): DESIGN's metrics.json for one policy, plus `policy`,
`resampling` (n_boot, n_perm, seed), `average` (mean SR and CV over the single-factor splits
present, the paper's "Average" column; CV null if any split's is), `cv_bias` in each split, and in each
interaction `n_instances`, `sr_ci95`, `cv_ci95`, `cv_bias`, `iec_ci95`, `iec_bias`, `p_value`
(per factor) and `per_value` ("a|b" → sr, n_episodes). `compute_all_metrics`
returns that dict for a single policy and {"epsilon", "resampling", "policies": {name: dict}} for
several; `policy_layouts` reads either shape back.
"""

from __future__ import annotations

import logging
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from roboview_data.factors import FACTORS

log = logging.getLogger(__name__)

EPSILON = 1e-6
Z95 = 1.959963984540054  # standard normal 97.5 % quantile
# Columns the metrics read; the rest of the episode record is carried along untouched.
METRIC_COLUMNS = ("policy", "split", "factor", "value", "context_id", "instance_id", "success")
_PERM_TOLERANCE = 1e-12  # float noise when a permutation reproduces the observed cells exactly


@dataclass(frozen=True)
class MetricsConfig:
    """How metrics are computed; the same config and table always give the same numbers."""

    # ε in the CV and IEC denominators (DESIGN default 1e-6).
    epsilon: float = EPSILON
    # Bootstrap replicates for cv_ci95 / iec_ci95.
    n_boot: int = 1000
    # Permutations for p_value.
    n_perm: int = 1000
    # Seed of the bootstrap and permutation generators (one stream per split and purpose).
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.epsilon > 0:
            raise ValueError(f"epsilon={self.epsilon} must be > 0 (it keeps CV finite at SR = 0)")
        if self.n_boot < 1 or self.n_perm < 1:
            raise ValueError(f"n_boot={self.n_boot} and n_perm={self.n_perm} must be ≥ 1")
        if self.seed < 0:
            raise ValueError(f"seed={self.seed} must be ≥ 0")


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


def conditional_cv(sr: np.ndarray, groups: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """σ / (μ + ε) of `sr` within each group (the paper's CCV), vectorized over leading axes.

    `sr` has shape (..., n_items); `groups` gives each item's group code 0..G-1 (every code
    present). Returns shape (..., G). Used for CV(V|c) and, one level up, for IEC.
    """
    counts = np.bincount(groups)
    mean = _group_sum(sr, groups) / counts
    var = _group_sum((sr - mean[..., groups]) ** 2, groups) / counts
    return np.sqrt(var) / (mean + epsilon)


def _group_sum(x: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Sum of x's last axis within each group code (reduceat over a stable sort)."""
    order = np.argsort(groups, kind="stable")
    starts = np.searchsorted(groups[order], np.arange(groups.max() + 1))
    return np.add.reduceat(x[..., order], starts, axis=-1)


def _codes(frame: pd.DataFrame, columns: Sequence[str]) -> np.ndarray:
    return frame.groupby(list(columns), sort=True).ngroup().to_numpy()


@dataclass(frozen=True)
class _Cells:
    """One split's episodes reduced to instance and cell success counts (all statistics need)."""

    factors: tuple[str, ...]
    cells: pd.DataFrame  # one row per cell: factor columns, context_id, n, k
    inst_cell: np.ndarray  # cell code of each instance
    inst_n: np.ndarray
    inst_k: np.ndarray

    @property
    def sr(self) -> np.ndarray:
        return (self.cells["k"] / self.cells["n"]).to_numpy()

    def codes(self, columns: Sequence[str]) -> np.ndarray:
        return _codes(self.cells, columns)


def _aggregate(episodes: pd.DataFrame, factors: tuple[str, ...]) -> _Cells:
    """Instances and cells of one split (`check_episodes` has vouched for its consistency)."""
    inst = episodes.groupby("instance_id", sort=True).agg(
        n=("success", "size"), k=("success", "sum"), value=("value", "first"), context_id=("context_id", "first"))
    parts = inst["value"].astype(str).str.split("|", regex=False)
    for i, name in enumerate(factors):
        inst[name] = parts.str[i]
    keys = [*factors, "context_id"]
    inst["cell"] = _codes(inst, keys)
    cells = inst.groupby("cell", sort=True).agg(
        n=("n", "sum"), k=("k", "sum"), **{key: (key, "first") for key in keys})
    return _Cells(factors, cells.reset_index(drop=True), inst["cell"].to_numpy(),
                  inst["n"].to_numpy(), inst["k"].to_numpy().astype(np.int64))


def _rng(cfg: MetricsConfig, split: str, purpose: str) -> np.random.Generator:
    """A stream per (seed, split, purpose): a split's CI never depends on which others exist."""
    return np.random.default_rng([cfg.seed, zlib.crc32(f"{split}:{purpose}".encode())])


def _bootstrap_sr(cells: _Cells, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, n_cells) cell SRs with every instance's episodes resampled with replacement."""
    k = rng.binomial(cells.inst_n, cells.inst_k / cells.inst_n, size=(n_boot, len(cells.inst_n)))
    return _group_sum(k, cells.inst_cell) / cells.cells["n"].to_numpy()


def _permuted_sr(cells: _Cells, groups: np.ndarray, n_perm: int, rng: np.random.Generator) -> np.ndarray:
    """(n_perm, n_cells) cell SRs with episode labels shuffled among the cells of each group."""
    n, k = cells.cells["n"].to_numpy(), cells.cells["k"].to_numpy()
    out = np.empty((n_perm, len(n)))
    for g in range(groups.max() + 1):
        idx = np.flatnonzero(groups == g)
        draws = rng.multivariate_hypergeometric(n[idx], int(k[idx].sum()), size=n_perm)
        out[:, idx] = draws / n[idx]
    return out


def _ci(samples: np.ndarray, point: float) -> list[float]:
    """The replicates' 95 % spread around `point` (see module docstring for why not percentile)."""
    lo, mid, hi = np.percentile(samples, [2.5, 50, 97.5])
    return [max(0.0, float(point + lo - mid)), float(point + hi - mid)]


def _bias(samples: np.ndarray, point: float) -> float:
    return float(np.mean(samples) - point)


def _p_value(observed: float, permuted: np.ndarray) -> float:
    return float((1 + np.sum(permuted >= observed - _PERM_TOLERANCE)) / (1 + len(permuted)))


def _value_order(factor: str, values: Sequence[str]) -> list[str]:
    """Registry order (rings, yaw-major, k) where the factor is known, then the rest sorted."""
    known = FACTORS[factor].values if factor in FACTORS else ()
    present = set(values)
    return [v for v in known if v in present] + sorted(present - set(known))


def _interval(successes: int, n: int) -> list[float] | None:
    ci = wilson_interval(successes, n)
    return None if ci is None else [ci[0], ci[1]]


def split_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """SR, CV (with CI and bias), p-value and per-value numbers of one single-factor split.

    `episodes` holds one split of one policy, validated by `check_episodes`. per_value[v]:
    `sr` = successes / episodes of v over all contexts; `signed_dev` = mean over the contexts c
    that hold v of SR(v, c) − μ_v' SR(v', c) (μ over the values present in c) — how much easier
    (> 0) or harder (< 0) v is than the other values of its contexts, whatever those contexts'
    overall difficulty.
    """
    split = str(episodes["split"].iloc[0])
    factor = str(episodes["factor"].iloc[0])
    cells = _aggregate(episodes, (factor,))
    n, k = len(episodes), int(episodes["success"].sum())
    ctx = cells.codes(["context_id"])
    sr_cell = cells.sr
    per_value: dict[str, dict[str, Any]] = {}
    dev = sr_cell - (_group_sum(sr_cell, ctx) / np.bincount(ctx))[ctx]
    table = cells.cells.assign(dev=dev).groupby(factor)
    for value in _value_order(factor, list(table.groups)):
        rows = table.get_group(value)
        per_value[value] = {"sr": float(rows["k"].sum() / rows["n"].sum()),
                            "n_episodes": int(rows["n"].sum()),
                            "signed_dev": float(rows["dev"].mean())}
    out: dict[str, Any] = {"factor": factor, "n_instances": int(len(cells.inst_n)), "n_episodes": n,
                           "sr": k / n, "sr_ci95": _interval(k, n),
                           "cv": None, "cv_ci95": None, "cv_bias": None, "p_value": None,
                           "per_value": per_value}
    if k == 0:
        return out

    def statistic(sr: np.ndarray) -> np.ndarray:
        return conditional_cv(sr, ctx, cfg.epsilon).mean(axis=-1)

    out["cv"] = float(statistic(sr_cell))
    boot = statistic(_bootstrap_sr(cells, cfg.n_boot, _rng(cfg, split, "boot")))
    out["cv_ci95"], out["cv_bias"] = _ci(boot, out["cv"]), _bias(boot, out["cv"])
    out["p_value"] = _p_value(out["cv"], statistic(_permuted_sr(cells, ctx, cfg.n_perm, _rng(cfg, split, "perm"))))
    return out


def _factorial_statistics(cells: _Cells, epsilon: float) -> tuple[Callable, dict[str, np.ndarray]]:
    """(cell SRs (..., n_cells) → {A, B, "A|B", "B|A"} arrays; each factor's cell groups (b, c) / (a, c))."""
    a, b = cells.factors
    by = {a: cells.codes([b, "context_id"]), b: cells.codes([a, "context_id"])}
    # Context of each (b, c) / (a, c) group, to average CV(A|b,c) over b within c for IEC.
    group_ctx = {f: _codes(cells.cells.assign(g=by[f]).groupby("g").first(), ["context_id"]) for f in (a, b)}

    def stats(sr: np.ndarray) -> dict[str, np.ndarray]:
        res: dict[str, np.ndarray] = {}
        for f, other in ((a, b), (b, a)):
            ccv = conditional_cv(sr, by[f], epsilon)
            res[f] = ccv.mean(axis=-1)
            res[f"{f}|{other}"] = conditional_cv(ccv, group_ctx[f], epsilon).mean(axis=-1)
        return res

    return stats, by


def interaction_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """SR, cv per factor, IEC both ways (with bootstrap CIs) and p-values of a two-factor split."""
    split = str(episodes["split"].iloc[0])
    a, b = str(episodes["factor"].iloc[0]).split("|")
    cells = _aggregate(episodes, (a, b))
    n, k = len(episodes), int(episodes["success"].sum())
    pooled = cells.cells.groupby([a, b], sort=False)[["n", "k"]].sum()
    order = {f: {v: i for i, v in enumerate(_value_order(f, cells.cells[f].unique()))} for f in (a, b)}
    keys = sorted(pooled.index, key=lambda ab: (order[a][ab[0]], order[b][ab[1]]))
    per_value = {f"{va}|{vb}": {"sr": float(pooled.loc[(va, vb), "k"] / pooled.loc[(va, vb), "n"]),
                                "n_episodes": int(pooled.loc[(va, vb), "n"])} for va, vb in keys}
    names = (a, b, f"{a}|{b}", f"{b}|{a}")
    out: dict[str, Any] = {"factors": [a, b], "n_instances": int(len(cells.inst_n)), "sr": k / n,
                           "sr_ci95": _interval(k, n), "n_episodes": n,
                           **{key: dict.fromkeys((a, b)) for key in ("cv", "cv_ci95", "cv_bias")},
                           **{key: dict.fromkeys(names[2:]) for key in ("iec", "iec_ci95", "iec_bias")},
                           "p_value": {a: None, b: None}, "per_value": per_value}
    if k == 0:
        return out
    stats, by = _factorial_statistics(cells, cfg.epsilon)
    point = stats(cells.sr)
    boot = stats(_bootstrap_sr(cells, cfg.n_boot, _rng(cfg, split, "boot")))
    for name in names:
        kind = "cv" if name in (a, b) else "iec"
        out[kind][name] = float(point[name])
        out[f"{kind}_ci95"][name] = _ci(boot[name], out[kind][name])
        out[f"{kind}_bias"][name] = _bias(boot[name], out[kind][name])
    for f in (a, b):
        permuted = stats(_permuted_sr(cells, by[f], cfg.n_perm, _rng(cfg, split, f"perm:{f}")))
        out["p_value"][f] = _p_value(out["cv"][f], permuted[f])
    return out


class EpisodesError(ValueError):
    """An episodes table the metrics cannot be computed from; the message names what is wrong."""


def check_episodes(episodes: pd.DataFrame, required: Sequence[str] = METRIC_COLUMNS, source: str = "episodes") -> None:
    """Raise EpisodesError unless every metric's assumption about the table holds.

    Required columns present and non-null, success boolean, one factor per split with values of
    as many '|'-joined parts, and one split, value and context per instance (per policy).
    """
    missing = [c for c in required if c not in episodes.columns]
    if missing:
        raise EpisodesError(f"{source} lacks column(s) {', '.join(missing)} (DESIGN.md, 'Episode record')")
    nulls = [c for c in required if episodes[c].isna().any()]
    if nulls:
        raise EpisodesError(f"{source} has null values in column(s) {', '.join(nulls)}")
    if episodes.empty:
        raise EpisodesError(f"{source} holds no episodes")
    bad = ~episodes["success"].isin([0, 1])
    if bad.any():
        raise EpisodesError(f"{source}: column success must be boolean; found {episodes['success'][bad].iloc[0]!r}")
    factors = episodes.groupby("split")["factor"].unique()
    for split, names in factors.items():
        if len(names) != 1:
            raise EpisodesError(f"{source}: split {split!r} mixes factors {sorted(map(str, names))}")
        n_parts = episodes.loc[episodes["split"] == split, "value"].astype(str).str.count(r"\|") + 1
        if (n_parts != len(str(names[0]).split("|"))).any():
            raise EpisodesError(f"{source}: split {split!r} has values that do not match factor {names[0]!r} "
                                "('|'-joined, one part per factor)")
    per_instance = episodes.groupby(["policy", "instance_id"])[["split", "value", "context_id"]].nunique()
    mixed = per_instance.index[(per_instance > 1).any(axis=1)]
    if len(mixed):
        raise EpisodesError(f"{source}: instance {mixed[0][1]!r} of policy {mixed[0][0]!r} has episodes with "
                            "different split, value or context_id; an instance fixes all three")


def compute_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """metrics.json layout (DESIGN.md) for the episodes of one policy."""
    check_episodes(episodes)
    policies = episodes["policy"].unique()
    if len(policies) != 1:
        raise ValueError(f"compute_metrics takes one policy, got {sorted(map(str, policies))}; "
                         "use compute_all_metrics")
    episodes = episodes.assign(success=episodes["success"].astype(np.int64))
    splits: dict[str, Any] = {}
    interactions: dict[str, Any] = {}
    for split, rows in episodes.groupby("split", sort=False):
        n_factors = len(str(rows["factor"].iloc[0]).split("|"))
        if n_factors == 1:
            splits[str(split)] = split_metrics(rows, cfg)
        elif n_factors == 2:
            interactions[str(split)] = interaction_metrics(rows, cfg)
        else:
            log.warning("split %s crosses %d factors; IEC is pairwise, so it is left out", split, n_factors)
    srs = [s["sr"] for s in splits.values()]
    cvs = [s["cv"] for s in splits.values()]
    average = {"sr": float(np.mean(srs)) if srs else None,
               "cv": float(np.mean(cvs)) if cvs and None not in cvs else None}
    return {"epsilon": cfg.epsilon, "policy": str(policies[0]),
            "resampling": {"n_boot": cfg.n_boot, "n_perm": cfg.n_perm, "seed": cfg.seed},
            "splits": splits, "interactions": interactions, "average": average}


def compute_all_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """One policy: `compute_metrics`. Several: {"epsilon", "resampling", "policies": {name: …}}."""
    check_episodes(episodes)
    names = sorted(map(str, episodes["policy"].unique()))
    if len(names) == 1:
        return compute_metrics(episodes, cfg)
    return {"epsilon": cfg.epsilon,
            "resampling": {"n_boot": cfg.n_boot, "n_perm": cfg.n_perm, "seed": cfg.seed},
            "policies": {name: compute_metrics(episodes[episodes["policy"] == name], cfg) for name in names}}


def policy_layouts(metrics: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """policy name → single-policy layout, for either shape `compute_all_metrics` returns."""
    if "policies" in metrics:
        return dict(metrics["policies"])
    return {metrics["policy"]: metrics}
