"""Bias metrics of paper §5.4 made exact, and the statistics that say whether they are more than noise.

Every key computed here is defined once, in docs/statistics.md ("metrics.json keys"); the episode columns it
reads are docs/formats.md's "Episode records". Everything is a pure function of an episodes table. Notation: a
*cell* is a value v (or a value pair (a, b) in a factorial split) in a context c; SR(v, c) is the mean success
over every episode of the instances in that cell.

Output (`compute_metrics`, one policy): `epsilon`, `policy`, `resampling` (n_perm, n_glm, seed), `control`,
`splits`, `interactions` and `average` (mean SR, CV and cv_excess over the single-factor splits present).
`compute_all_metrics` returns that dict for a single policy and {"epsilon", "resampling", "policies": {name:
dict}, "comparisons" (`roboview.eval.statistics.compare`), "rankings" (three policies or more)} for several; `policy_layouts`
reads either shape back.

Episodes that infrastructure ended (`status` `infra_error`, docs/evaluation.md "Infrastructure errors") enter
no number: both functions drop them (`roboview.eval.running.results.counted`) and count them, per split `n_infra_errors` and per
policy `n_infra_errors` (their total).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.running import isolation
from roboview.eval.running.results import copies_mask, counted, infra_mask
from roboview.eval.statistics import ranking
from roboview.eval.statistics import significance as stats
from roboview.eval.statistics.analyses import task_analyses
from roboview.eval.statistics.compare import (
    all_baseline,
    baseline_retest,
    compare_policies,
    control_arm,
    control_deltas,
)
from roboview.eval.statistics.intervals import cv_excess_interval
from roboview.eval.statistics.tables import (  # noqa: F401 — re-exported: the metrics' vocabulary
    EPSILON,
    SEQUENTIAL_H,
    Z95,
    CellTable,
    MetricsConfig,
    codes,
    conditional_cv,
    excess,
    group_sum,
    rate_ci95,
    rate_interval,
    value_order,
)

log = logging.getLogger(__name__)

# Columns the metrics read; the rest of the episode record is carried along untouched.
METRIC_COLUMNS = ("policy", "split", "factor", "value", "context_id", "instance_id", "repeat", "success")


def _table(episodes: pd.DataFrame, factors: tuple[str, ...]) -> CellTable:
    """Cells (value(s) × context) of one split (`check_episodes` has vouched for its consistency)."""
    eps = episodes[["value", "context_id", "repeat", "success", "instance_id"]].copy()
    parts = eps["value"].astype(str).str.split("|", regex=False)
    for i, name in enumerate(factors):
        eps[name] = parts.str[i]
    return CellTable.build(eps, factors, [*factors, "context_id"])


def _per_value_tests(table: CellTable, factor: str) -> dict[str, stats.ValueTest]:
    """CMH odds ratio of each value against the rest, stratified by block (context, repeat)."""
    eps = table.episodes
    grid = eps.groupby(["context_id", "repeat", factor], sort=True)["success"].agg(["sum", "size"])
    k = grid["sum"].unstack(factor, fill_value=0)
    n = grid["size"].unstack(factor, fill_value=0)
    k_all, n_all = k.sum(axis=1).to_numpy(), n.sum(axis=1).to_numpy()
    return {str(v): stats.value_vs_rest(k[v].to_numpy(), n[v].to_numpy(), k_all, n_all) for v in k.columns}


def split_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """SR, CV and its statistics, and per-value numbers of one single-factor split.

    `episodes` holds one split of one policy, validated by `check_episodes`. per_value[v]:
    `sr` = successes / episodes of v over all contexts; `signed_dev` = mean over the contexts c
    that hold v of SR(v, c) − μ_v' SR(v', c) (μ over the values present in c) — how much easier
    (> 0) or harder (< 0) v is than the other values of its contexts; then the CMH numbers.
    """
    split = str(episodes["split"].iloc[0])
    factor = str(episodes["factor"].iloc[0])
    table = _table(episodes, (factor,))
    n, k = len(episodes), int(episodes["success"].sum())
    ctx = table.codes(["context_id"])
    ctx_k = np.bincount(ctx, weights=table.k)
    out: dict[str, Any] = {
        "factor": factor,
        "n_instances": int(episodes["instance_id"].nunique()),
        "n_episodes": n,
        "n_contexts": int(ctx.max() + 1),
        "n_contexts_all_failed": int(np.sum(ctx_k == 0)),
        "sr": k / n,
        "sr_ci95": rate_ci95(k, n),
        "cv": None,
        "cv_null": None,
        "cv_excess": None,
        "cv_excess_ci95": None,
        **stats.lrt_fields(None),
        "p_value_cv": None,
        "p_value_cv_draws": None,
        "p_value_cv_at_floor": None,
        "per_value": _split_per_value(table, factor, ctx, tested=k > 0),
    }
    if k:
        out |= _cv_tests(table, factor, ctx, cfg.rng(split, "perm"), cfg)
        out["cv_excess_ci95"] = cv_excess_interval(
            table, ctx, out["cv"], out["cv_excess"], cfg.n_boot, cfg.epsilon, cfg.rng(split, "boot")
        )
    return out


def _split_per_value(
    table: CellTable, factor: str, ctx: np.ndarray, tested: bool
) -> dict[str, dict[str, Any]]:
    """value → SR (with its Clopper–Pearson interval), episodes, signed deviation from its contexts' mean, and
    (`tested`) the CMH test against the rest with its Benjamini-Hochberg q over the values."""
    sr_cell = table.sr
    dev = sr_cell - (group_sum(sr_cell, ctx) / np.bincount(ctx))[ctx]
    tests = _per_value_tests(table, factor) if tested else {}
    grouped = table.cells.assign(dev=dev).groupby(factor)
    per_value: dict[str, dict[str, Any]] = {}
    for value in value_order(factor, list(grouped.groups)):
        rows = grouped.get_group(value)
        test = tests.get(value, stats.ValueTest(None, None, None))
        k, n = int(rows["k"].sum()), int(rows["n"].sum())
        per_value[value] = {
            "sr": k / n,
            "sr_ci95": rate_ci95(k, n),
            "n_episodes": n,
            "signed_dev": float(rows["dev"].mean()),
            "odds_ratio": test.odds_ratio,
            "odds_ratio_ci95": test.odds_ratio_ci95,
            "p_value": test.p_value,
        }
    for value, q in zip(per_value, stats.benjamini_hochberg([m["p_value"] for m in per_value.values()])):
        per_value[value]["q_value"] = q
    return per_value


# A single repeat leaves the CV's permutation floor undefined: its fields when that is so.
CV_UNMEASURED = {
    "cv_null": None,
    "cv_excess": None,
    "p_value_cv": None,
    "p_value_cv_draws": None,
    "p_value_cv_at_floor": None,
}


def _cv_tests(
    table: CellTable, factor: str, ctx: np.ndarray, rng: np.random.Generator, cfg: MetricsConfig
) -> dict[str, Any]:
    """CV against its permutation null (values shuffled within context): cv, cv_null, cv_excess, the sequential
    Monte Carlo p, then the GLM likelihood-ratio test of the factor on the first `n_glm` permutations."""

    def statistic(sr: np.ndarray) -> np.ndarray:
        return conditional_cv(sr, ctx, cfg.epsilon).mean(axis=-1)

    permuted = table.permuted_k(["context_id"], cfg.n_perm, rng)
    if table.n.max() == 1:
        # One episode per cell (a single repeat): shuffling the values within a (context, repeat) block keeps each
        # context's outcomes, so every permuted CV equals the CV. There is no noise floor to measure it against,
        # and cv_excess would read 0 whatever the bias; the GLM test still uses the permutations.
        glm = _glm_test(table, table.codes([factor]), ctx, permuted, ["context_id"], rng, cfg)
        return {"cv": float(statistic(table.sr)), **CV_UNMEASURED, **stats.lrt_fields(glm)}
    null = statistic(permuted / table.n)
    cv, cv_null = float(statistic(table.sr)), float(null.mean())
    mc = stats.sequential_p(
        cv,
        null,
        lambda b: statistic(table.permuted_k(["context_id"], b, rng) / table.n),
        SEQUENTIAL_H,
        cfg.max_perm,
    )
    lrt = _glm_test(table, table.codes([factor]), ctx, permuted, ["context_id"], rng, cfg)
    return {
        "cv": cv,
        "cv_null": cv_null,
        "cv_excess": excess(cv, cv_null),
        "p_value_cv": mc.p_value,
        "p_value_cv_draws": mc.draws,
        "p_value_cv_at_floor": mc.at_floor,
        **stats.lrt_fields(lrt),
    }


def _glm_test(
    table: CellTable,
    value: np.ndarray,
    strata: np.ndarray,
    permuted: np.ndarray,
    within: list[str],
    rng: np.random.Generator,
    cfg: MetricsConfig,
) -> stats.LRT | None:
    """The factor's GLM likelihood-ratio test, permutation-calibrated on the first n_glm of `permuted` (value labels
    shuffled within `within` and repeat); beyond their floor, more permutations drawn from `rng` up to max_glm, else
    the stretched χ² tail."""
    return stats.factor_lrt(
        table.k,
        table.n,
        value,
        strata,
        permuted[: cfg.n_glm],
        lambda size: table.permuted_k(within, size, rng),
        cfg.max_glm,
        stretch_tail=True,
    )


def _factorial_statistics(table: CellTable, epsilon: float) -> tuple[Callable, dict[str, np.ndarray]]:
    """(cell SRs (..., n_cells) → {A, B, "A|B", "B|A"} arrays; each factor's cell groups (b, c) / (a, c))."""
    a, b = table.factors
    by = {a: table.codes([b, "context_id"]), b: table.codes([a, "context_id"])}
    # Context of each (b, c) / (a, c) group, to average CV(A|b,c) over b within c for IEC.
    group_ctx = {f: codes(table.cells.assign(g=by[f]).groupby("g").first(), ["context_id"]) for f in (a, b)}

    def statistics(sr: np.ndarray) -> dict[str, np.ndarray]:
        res: dict[str, np.ndarray] = {}
        for f, other in ((a, b), (b, a)):
            ccv = conditional_cv(sr, by[f], epsilon)
            res[f] = ccv.mean(axis=-1)
            res[f"{f}|{other}"] = conditional_cv(ccv, group_ctx[f], epsilon).mean(axis=-1)
        return res

    return statistics, by


def interaction_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """SR, CV per factor, IEC both ways, each against its null, and the tests of a two-factor split."""
    split = str(episodes["split"].iloc[0])
    a, b = str(episodes["factor"].iloc[0]).split("|")
    table = _table(episodes, (a, b))
    n, k = len(episodes), int(episodes["success"].sum())
    iec_names = (f"{a}|{b}", f"{b}|{a}")
    out: dict[str, Any] = {
        "factors": [a, b],
        "n_instances": int(episodes["instance_id"].nunique()),
        "sr": k / n,
        "sr_ci95": rate_ci95(k, n),
        "n_episodes": n,
        **{
            key: dict.fromkeys((a, b))
            for key in ("cv", "cv_null", "cv_excess", "p_value", "p_value_method", "p_value_cv")
        },
        **{key: dict.fromkeys(iec_names) for key in ("iec", "iec_null", "iec_excess", "p_iec")},
        "p_interaction": None,
        "p_interaction_method": None,
        "per_value": _pair_per_value(table),
    }
    if k == 0:
        return out
    statistics, by = _factorial_statistics(table, cfg.epsilon)
    point = statistics(table.sr)
    for f, other in ((a, b), (b, a)):
        _factor_tests(out, table, f, other, statistics, point, by[f], split, cfg)
    _interaction_tests(out, table, statistics, point, split, cfg)
    return out


def _pair_per_value(table: CellTable) -> dict[str, dict[str, Any]]:
    """ "a|b" → SR and episodes of the value pair pooled over contexts, in both factors' value order."""
    a, b = table.factors
    pooled = table.cells.groupby([a, b], sort=False)[["n", "k"]].sum()
    order = {f: {v: i for i, v in enumerate(value_order(f, table.cells[f].unique()))} for f in (a, b)}
    keys = sorted(pooled.index, key=lambda ab: (order[a][ab[0]], order[b][ab[1]]))
    return {
        f"{va}|{vb}": {
            "sr": float(pooled.loc[(va, vb), "k"] / pooled.loc[(va, vb), "n"]),
            "n_episodes": int(pooled.loc[(va, vb), "n"]),
        }
        for va, vb in keys
    }


def _factor_tests(
    out: dict[str, Any],
    table: CellTable,
    f: str,
    other: str,
    statistics: Callable,
    point: dict[str, np.ndarray],
    groups: np.ndarray,
    split: str,
    cfg: MetricsConfig,
) -> None:
    """Factor `f`'s CV against its permutation null (values of f shuffled within (other, context)) and its GLM
    likelihood-ratio test, into `out`'s per-factor entries."""
    rng = cfg.rng(split, f"perm:{f}")
    permuted = table.permuted_k([other, "context_id"], cfg.n_perm, rng)
    null = statistics(permuted / table.n)[f]
    out["cv"][f] = float(point[f])
    out["cv_null"][f] = float(null.mean())
    out["cv_excess"][f] = excess(out["cv"][f], out["cv_null"][f])
    out["p_value_cv"][f] = stats.permutation_p(out["cv"][f], null)
    test = _glm_test(table, table.codes([f]), groups, permuted, [other, "context_id"], rng, cfg)
    out["p_value"][f] = None if test is None else test.p_value
    out["p_value_method"][f] = None if test is None else test.method


def _interaction_tests(
    out: dict[str, Any],
    table: CellTable,
    statistics: Callable,
    point: dict[str, np.ndarray],
    split: str,
    cfg: MetricsConfig,
) -> None:
    """The likelihood-ratio test of A×B against A + B, and both IECs against their null (tables drawn from the
    fitted additive model), into `out`."""
    a, b = table.factors
    test, draws = stats.interaction_lrt(
        table.k,
        table.n,
        table.codes([a]),
        table.codes([b]),
        table.codes(["context_id"]),
        cfg.n_glm,
        cfg.rng(split, "additive"),
    )
    if test is not None:
        out["p_interaction"], out["p_interaction_method"] = test.p_value, test.method
    null_iec = statistics(draws / table.n) if draws is not None else None
    for name in (f"{a}|{b}", f"{b}|{a}"):
        out["iec"][name] = float(point[name])
        if null_iec is not None:
            out["iec_null"][name] = float(null_iec[name].mean())
            out["iec_excess"][name] = excess(out["iec"][name], out["iec_null"][name])
            out["p_iec"][name] = stats.permutation_p(out["iec"][name], null_iec[name])


class EpisodesError(ValueError):
    """An episodes table the metrics cannot be computed from; the message names what is wrong."""


def check_episodes(
    episodes: pd.DataFrame, required: Sequence[str] = METRIC_COLUMNS, source: str = "episodes"
) -> None:
    """Raise EpisodesError unless every metric's assumption about the table holds.

    Required columns present and non-null, success boolean, one factor per split with values of
    as many '|'-joined parts, and one split, value and context per instance (per policy).
    """
    missing = [c for c in required if c not in episodes.columns]
    if missing:
        raise EpisodesError(
            f"{source} lacks column(s) {', '.join(missing)} (docs/formats.md, 'Episode records')"
        )
    nulls = [c for c in required if episodes[c].isna().any()]
    if nulls:
        raise EpisodesError(f"{source} has null values in column(s) {', '.join(nulls)}")
    if episodes.empty:
        raise EpisodesError(f"{source} holds no episodes")
    bad = ~episodes["success"].isin([0, 1])
    if bad.any():
        raise EpisodesError(
            f"{source}: column success must be boolean; found {episodes['success'][bad].iloc[0]!r}"
        )
    factors = episodes.groupby("split")["factor"].unique()
    for split, names in factors.items():
        if len(names) != 1:
            raise EpisodesError(f"{source}: split {split!r} mixes factors {sorted(map(str, names))}")
        n_parts = episodes.loc[episodes["split"] == split, "value"].astype(str).str.count(r"\|") + 1
        if (n_parts != len(str(names[0]).split("|"))).any():
            raise EpisodesError(
                f"{source}: split {split!r} has values that do not match factor {names[0]!r} "
                "('|'-joined, one part per factor)"
            )
    per_instance = episodes.groupby(["policy", "instance_id"])[["split", "value", "context_id"]].nunique()
    mixed = per_instance.index[(per_instance > 1).any(axis=1)]
    if len(mixed):
        raise EpisodesError(
            f"{source}: instance {mixed[0][1]!r} of policy {mixed[0][0]!r} has episodes with "
            "different split, value or context_id; an instance fixes all three"
        )


def _counted_episodes(episodes: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, int], dict[str, int]]:
    """The episodes that count, split → episodes infrastructure ended and split → seed-only copies (left out)."""
    infra = episodes.loc[infra_mask(episodes), "split"].astype(str).value_counts()
    copies = episodes.loc[copies_mask(episodes), "split"].astype(str).value_counts()
    kept = counted(episodes)
    if kept.empty:
        raise EpisodesError(
            f"all {len(episodes)} episode(s) ended by infrastructure (status infra_error), not by "
            "the policy: nothing to measure; rerun the evaluation command to run them again"
        )
    return kept, {str(s): int(n) for s, n in infra.items()}, {str(s): int(n) for s, n in copies.items()}


def compute_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """metrics.json layout (docs/formats.md, "Metrics") for the episodes of one policy (episodes infrastructure
    ended are left out, and counted per split in `n_infra_errors`)."""
    check_episodes(episodes)
    episodes, infra, copies = _counted_episodes(episodes)
    policies = episodes["policy"].unique()
    if len(policies) != 1:
        raise ValueError(
            f"compute_metrics takes one policy, got {sorted(map(str, policies))}; use compute_all_metrics"
        )
    # The isolation certificate first: blocks in which more than the factor changed leave the tests.
    certificate = isolation.verify(episodes)
    episodes = isolation.drop_violations(episodes, certificate)
    episodes = episodes.assign(success=episodes["success"].astype(np.int64))
    splits: dict[str, Any] = {}
    interactions: dict[str, Any] = {}
    baseline = all_baseline(episodes)  # every split's control arm is drawn from it
    for split, rows in episodes.groupby("split", sort=False):
        n_factors = len(str(rows["factor"].iloc[0]).split("|"))
        extra = {
            "isolation": certificate[str(split)],
            "n_infra_errors": infra.get(str(split), 0),
            # Results of the seed-only design on LIBERO's scenes: repeats that copied repeat 0, left out.
            **({"n_seed_only_copies": copies[str(split)]} if str(split) in copies else {}),
            **control_arm(baseline, rows),
        }
        if n_factors == 1:
            splits[str(split)] = split_metrics(rows, cfg) | extra
            for value, delta in control_deltas(baseline, rows).items():
                splits[str(split)]["per_value"].get(value, {}).update(delta)
        elif n_factors == 2:
            interactions[str(split)] = interaction_metrics(rows, cfg) | extra
        else:
            log.warning("split %s crosses %d factors; IEC is pairwise, so it is left out", split, n_factors)
    average: dict[str, float | None] = {"sr": None, "cv": None, "cv_excess": None}
    for key in average:
        values = [s[key] for s in splits.values()]
        average[key] = float(np.mean(values)) if values and None not in values else None
    out = {
        "epsilon": cfg.epsilon,
        "policy": str(policies[0]),
        "resampling": _resampling(cfg),
        "control": baseline_retest(episodes),
        "splits": splits,
        "interactions": interactions,
        "average": average,
        "n_infra_errors": sum(infra.values()),
    }
    analyses = task_analyses(episodes)
    if analyses:
        out["analyses"] = analyses
    return out


def compute_all_metrics(episodes: pd.DataFrame, cfg: MetricsConfig = MetricsConfig()) -> dict[str, Any]:
    """One policy: `compute_metrics`. Several: {"epsilon", "resampling", "policies": {name: …}}. Episodes that
    infrastructure ended are left out of every number (and counted)."""
    check_episodes(episodes)
    kept, _, _ = _counted_episodes(episodes)
    names = sorted(map(str, kept["policy"].unique()))
    if len(names) == 1:
        return compute_metrics(episodes, cfg)
    # Paired comparisons see only the blocks each policy's certificate verified.
    certified = pd.concat(
        [
            isolation.drop_violations(rows, isolation.verify(rows))
            for _, rows in kept.groupby("policy", sort=False)
        ]
    )
    out = {
        "epsilon": cfg.epsilon,
        "resampling": _resampling(cfg),
        "policies": {name: compute_metrics(episodes[episodes["policy"] == name], cfg) for name in names},
        "comparisons": compare_policies(certified, cfg),
    }
    ranked = ranking.rankings(out, certified)
    if ranked is not None:  # three or more policies
        out["rankings"] = ranked
    return out


def _resampling(cfg: MetricsConfig) -> dict[str, int]:
    return {
        "n_perm": cfg.n_perm,
        "n_glm": cfg.n_glm,
        "max_perm": cfg.max_perm,
        "max_glm": cfg.max_glm,
        "n_boot": cfg.n_boot,
        "seed": cfg.seed,
    }


def policy_layouts(metrics: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """policy name → single-policy layout, for either shape `compute_all_metrics` returns."""
    if "policies" in metrics:
        return dict(metrics["policies"])
    return {metrics["policy"]: metrics}
