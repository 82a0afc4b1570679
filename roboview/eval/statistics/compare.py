"""Two policies on the same benchmark, compared within instances (docs/statistics.md, "metrics.json keys": comparisons).

Common random numbers make this a matched design: repeat r of an instance runs with the same seed
(same jitter, same heading) whatever the policy, so policy A's and policy B's episodes of one
(instance, repeat) are pairs. Only pairs both policies ran are compared.

- `delta_sr` = SR(B) − SR(A) over the pairs; `p_sr`: McNemar's test on the pairs (statsmodels).
- `delta_cv_excess` = cv_excess(B) − cv_excess(A) over the pairs; `p_cv_excess`: a paired
  permutation test (scipy `permutation_test`, permutation_type="samples"): under "the two policies
  are interchangeable" swapping which policy ran an instance (all its repeats) changes nothing, so
  the observed difference is compared with differences after random swaps. cv_excess here uses a
  fixed, smaller permutation count for its noise floor (`n_inner`), identical for every swap.
"""

from __future__ import annotations

import itertools
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from roboview.eval.statistics.significance import paired_success_test
from roboview.eval.statistics.tables import (
    MetricsConfig,
    codes,
    conditional_cv,
    excess,
    group_sum,
    paired_difference_ci95,
    rate_ci95,
)

N_INNER = 100  # permutations behind each swap's noise floor
N_SWAPS = 200  # swaps behind p_cv_excess


@dataclass(frozen=True)
class _Paired:
    """One single-factor split's instances × common repeats, success matrices for both policies."""

    a: np.ndarray  # (n_instances, n_repeats) bool, policy A
    b: np.ndarray
    cell: np.ndarray  # cell code (value, context) of each instance
    context: np.ndarray  # context code of each cell
    epsilon: float

    def cv_excess(self, success: np.ndarray, seed: int) -> float | None:
        """cv against its within-(context, repeat) permutation floor for one success matrix; None when nothing
        succeeded, or with one episode per cell, where every permutation leaves the CV as it is (no floor)."""
        n_rep = success.shape[1]
        n_cell = np.bincount(self.cell) * n_rep
        if not success.any() or n_cell.max() == 1:
            return None
        cv = conditional_cv(
            group_sum(success.sum(axis=1), self.cell) / n_cell, self.context, self.epsilon
        ).mean()
        rng = np.random.default_rng(seed)
        inst_ctx = self.context[self.cell]
        perm_k = np.zeros((N_INNER, len(self.cell)))
        for c in np.unique(inst_ctx):
            idx = np.flatnonzero(inst_ctx == c)
            block = np.broadcast_to(success[idx], (N_INNER, *success[idx].shape))
            perm_k[:, idx] = rng.permuted(block, axis=1).sum(axis=2)  # shuffle instances within (c, r)
        null = conditional_cv(group_sum(perm_k, self.cell) / n_cell, self.context, self.epsilon).mean(axis=-1)
        return excess(float(cv), float(null.mean()))


def _paired(rows: pd.DataFrame, name_a: str, name_b: str, epsilon: float) -> _Paired | None:
    wide = rows.pivot_table(
        index=["instance_id", "repeat"], columns="policy", values="success", aggfunc="first"
    )
    wide = wide.dropna()
    if wide.empty:
        return None
    counts = wide.groupby(level="instance_id").size()
    n_rep = int(counts.min())
    wide = wide.groupby(level="instance_id").head(n_rep)  # the same number of pairs per instance
    inst = (
        rows.drop_duplicates("instance_id")
        .set_index("instance_id")
        .loc[counts.index, ["value", "context_id"]]
    )
    cell = codes(inst, ["value", "context_id"])
    context = codes(inst.assign(cell=cell).groupby("cell").first(), ["context_id"])
    shape = (len(counts), n_rep)
    return _Paired(
        wide[name_a].to_numpy(bool).reshape(shape),
        wide[name_b].to_numpy(bool).reshape(shape),
        cell,
        context,
        epsilon,
    )


def compare_pair(
    rows: pd.DataFrame, name_a: str, name_b: str, cfg: MetricsConfig, split: str
) -> dict[str, Any] | None:
    """B against A on one split (rows hold both policies' episodes of it)."""
    paired = _paired(rows, name_a, name_b, cfg.epsilon)
    if paired is None:
        return None
    out: dict[str, Any] = {
        "split": split,
        "policies": [name_a, name_b],
        "n_pairs": int(paired.a.size),
        "delta_sr": float(paired.b.mean() - paired.a.mean()),
        "p_sr": paired_success_test(paired.a.ravel(), paired.b.ravel()),
        "delta_cv_excess": None,
        "p_cv_excess": None,
    }
    if "|" in str(rows["factor"].iloc[0]):
        return out  # factorial splits: paired SR only (their CV is per factor)
    seed = zlib.crc32(f"{cfg.seed}:{split}:{name_a}:{name_b}".encode())
    n = len(paired.cell)
    stacked = np.concatenate([paired.a, paired.b])  # row i: A's instance i; row n + i: B's

    def delta(x: np.ndarray, y: np.ndarray) -> float:
        ex, ey = (
            paired.cv_excess(stacked[x.astype(int)], seed),
            paired.cv_excess(stacked[y.astype(int)], seed),
        )
        return np.nan if ex is None or ey is None else ey - ex

    observed = delta(np.arange(n), np.arange(n, 2 * n))
    if np.isnan(observed):
        return out
    result = sps.permutation_test(
        (np.arange(n), np.arange(n, 2 * n)),
        delta,
        permutation_type="samples",
        vectorized=False,
        n_resamples=N_SWAPS,
        alternative="two-sided",
        rng=np.random.default_rng(seed),
    )
    null = result.null_distribution
    null = null[~np.isnan(null)]
    out["delta_cv_excess"] = float(observed)
    # Recomputed from the finite swaps (an all-fail swap has no CV), as scipy does: (1 + #≥) / (1 + B).
    out["p_cv_excess"] = float((1 + np.sum(np.abs(null) >= abs(observed) - 1e-12)) / (1 + len(null)))
    return out


def compare_policies(episodes: pd.DataFrame, cfg: MetricsConfig) -> list[dict[str, Any]]:
    """Every split × pair of policies (sorted names; B − A with A first alphabetically)."""
    names = sorted(map(str, episodes["policy"].unique()))
    out = []
    for split, rows in episodes.groupby("split", sort=True):
        present = [p for p in names if p in set(rows["policy"])]
        for name_a, name_b in itertools.combinations(present, 2):
            pair = rows[rows["policy"].isin([name_a, name_b])]
            result = compare_pair(pair, name_a, name_b, cfg, str(split))
            if result is not None:
                out.append(result)
    return out


def all_baseline(episodes: pd.DataFrame) -> pd.DataFrame | None:
    """The episodes of the all-baseline instances (every visual factor at its baseline in the row's task's world:
    LIBERO's color `original`, RoboView's red) of the single-factor splits; None when the table lacks the factor
    columns."""
    from roboview.variation.factors import DEFAULT_TASK, baseline_of, visual_factors

    # Results written before a factor existed lack its column: there it was at its baseline.
    present = [f for f in visual_factors() if f in episodes.columns]
    if not present:
        return None
    base = episodes[~episodes["factor"].astype(str).str.contains("|", regex=False)]
    named = base["task"].fillna(DEFAULT_TASK).astype(str) if "task" in base else None
    tasks = named if named is not None else pd.Series(DEFAULT_TASK, index=base.index)
    for factor in present:
        expected = tasks.map({task: baseline_of(factor, task) for task in tasks.unique()})
        base = base[base[factor].astype(str) == expected[base.index]]
    return base


def control_rows(base: pd.DataFrame | None, split_rows: pd.DataFrame) -> pd.DataFrame | None:
    """The episodes a split's values are compared against: its factor's reference value where it declares one
    (`Factor.reference`: scene_text's blank card, on the split's own contexts and seeds), else `base`, the
    all-baseline ones."""
    from roboview.variation.factors import FACTORS

    factor = str(split_rows["factor"].iloc[0]) if len(split_rows) and "factor" in split_rows else ""
    reference = FACTORS[factor].reference if factor in FACTORS else ""
    return split_rows[split_rows["value"].astype(str) == reference] if reference else base


def control_arm(base: pd.DataFrame | None, split_rows: pd.DataFrame) -> dict[str, Any]:
    """A split's control arm as result fields: the success of the all-baseline instance of each (context, repeat) the
    split ran, on the same seed (from whichever split ran it: they share the seed), with its Clopper–Pearson interval.
    `base`: the table's all-baseline episodes (`all_baseline`, selected once for every split). `sr_control` None
    where no such episode was run (a sample without the baseline value)."""
    pairs = set(zip(split_rows["context_id"], split_rows["repeat"]))
    base = control_rows(base, split_rows)
    if base is not None:
        base = base.loc[np.array([p in pairs for p in zip(base["context_id"], base["repeat"])], dtype=bool)]
        base = base.drop_duplicates(["context_id", "repeat"])
    n = 0 if base is None else len(base)
    k = 0 if base is None else int(base["success"].sum())
    return {
        "sr_control": k / n if n else None,
        "sr_control_ci95": rate_ci95(k, n),
        "n_control_episodes": n,
    }


def control_deltas(base: pd.DataFrame | None, split_rows: pd.DataFrame) -> dict[str, dict[str, Any]]:
    """Per value of a single-factor split, its paired difference to the control arm: `delta_control` = SR(value) −
    SR(control) over the (context, repeat) pairs both ran (same seed), `delta_control_ci95`, its 95 % interval
    (Newcombe's hybrid score interval for paired rates, `paired_difference_ci95`), `n_control_pairs`, and `p_control`,
    McNemar's test on those pairs (`paired_success_test`). Empty where no control episode was run."""
    base = control_rows(base, split_rows)
    if base is None or base.empty:
        return {}
    control = base.drop_duplicates(["context_id", "repeat"]).set_index(["context_id", "repeat"])["success"]
    out = {}
    for value, rows in split_rows.groupby("value", sort=False):
        joined = rows.set_index(["context_id", "repeat"])["success"].groupby(level=[0, 1]).first()
        both = joined.index.intersection(control.index)
        if not len(both):
            continue
        a = joined.loc[both].to_numpy().astype(bool)
        b = control.loc[both].to_numpy().astype(bool)
        out[str(value)] = {
            "delta_control": float(a.mean() - b.mean()),
            "delta_control_ci95": paired_difference_ci95(a, b),
            "n_control_pairs": int(len(both)),
            "p_control": paired_success_test(a, b),
        }
    return out


def baseline_retest(episodes: pd.DataFrame) -> dict[str, Any] | None:
    """The built-in control arm: the all-baseline instance of a context runs in several single-factor
    splits (color at its baseline: red in RoboView's scene, `original` in LIBERO's and Meta-World's; Euler (0, 0),
    distance 0) with the same seeds. Its outcomes should agree across
    splits; `agreement` is the share of (context, repeat) pairs seen in ≥ 2 splits whose outcomes all
    agree (1.0 for a deterministic policy), `sr_by_split` the baseline SR in each split.
    None when the table lacks the factor columns or no pair repeats."""
    base = all_baseline(episodes)
    if base is None:
        return None
    groups = base.groupby(["context_id", "repeat"])["success"]
    spread = groups.agg(["nunique", "size"])
    spread = spread[spread["size"] >= 2]
    if spread.empty:
        return None
    sr = base.groupby("split")["success"].mean()
    return {
        "n_pairs": int(len(spread)),
        "agreement": float(np.mean(spread["nunique"] == 1)),
        "sr_by_split": {str(s): float(v) for s, v in sr.items()},
    }
