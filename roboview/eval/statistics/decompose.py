"""A factor taken apart into its sub-factors: the analysis a task declares as a design (`Task.analyses`, a
`roboview.tasks.decomposition.Decomposition`), run on one policy's episodes of that task (metrics.json
`analyses.<key>`; LIBERO-plus's camera dimension is one, docs/liberoplus.md).

- **The factor's number** two ways over the external benchmark's own variants (`Decomposition.variant_splits`): the
  micro total (every variant episode weighted alike, so a group with more variants weighs more) and the macro one
  (each group's rate over its own variants, then the groups' mean). Beside it, the no-change view's rate. Where the
  rows carry the fairness gate's verdict (`gate_passed`, kept whatever it said), the same over the variants it passes
  (`fair`) and how many it does not.
- **Each kind of change against the no-change view**, paired by block (the same context, repeat and seed): per
  block, the kind's mean success minus the no-change episode's; the effect is the mean over blocks, its 95 % interval
  a bootstrap over blocks (scipy `bootstrap`, BCa), its p a sign-flip permutation test over blocks (scipy
  `permutation_test`: exact up to 16 blocks, 100,000 random flips beyond). Blocks, not episodes, are the independent
  units: one no-change episode pairs with every variant of its block.
- **Interaction**: for each two-change variant whose single-change parts ran in its block, S(both) − S(first) −
  S(second) + S(none) — 0 when the two costs add on the success scale, negative when together they cost more.
  Averaged per block, tested and bounded as above.
- **Dose–response** over each sub-factor's severity (`SubFactor.severity`, the no-change view at 0): a logistic GLM
  (statsmodels) of success on severity with standard errors clustered by context, the fitted success at 0, and the
  severity at which the fitted success falls to half of it, with a delta-method 95 % interval (None where success
  does not fall with severity).
- **Twins** (`Decomposition.twin`: LIBERO-plus's noise on the wrist camera too): the factor's number both ways over
  the twins of the external variants, and per kind the twins against their originals (the same variant with the
  twin's sub-factor at its no-change value, in the same block): the mean per block of twin minus original success,
  bounded and tested as above.
- **Per variant**, where repeats ran: its rate, its paired difference to the no-change view over the same blocks,
  that difference's interval and McNemar's test (`roboview.eval.statistics.compare.control_deltas`, as every split's
  values against the control arm).

Every rate's interval is Clopper–Pearson (`rate_ci95`). Validated against known truth by simulation
(tests/eval/statistics/test_decompose.py, tests/libero/test_plus_decomposition.py).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from roboview.benchmark.format import GATE_COLUMN
from roboview.eval.statistics.compare import control_deltas
from roboview.eval.statistics.tables import Z95, rate_ci95
from roboview.tasks.decomposition import Decomposition, SubFactor

N_BOOT = 2000
N_FLIPS = 100_000
EXACT_BLOCKS = 16  # 2**16 sign flips: enumerated exactly
SEED = 0
BLOCK = ["context_id", "repeat"]  # a block: one context from one repeat (its seed)


def views(rows: pd.DataFrame, design: Decomposition) -> pd.DataFrame:
    """Rows with integer sub-factor columns and `kind` (what the view changes, "+"-joined columns; "" for the
    no-change view)."""
    params = {f.column: rows[f.column].astype(int) for f in design.sub_factors}
    kind = pd.Series("", index=rows.index)
    for f in design.sub_factors:
        kind = kind.where(params[f.column] == f.no_change, kind + "+" + f.column)
    kind = kind.str.lstrip("+")
    return rows.assign(**params, kind=kind, success=rows["success"].astype(int))


def rate(success: pd.Series) -> dict[str, Any]:
    """The success rate with its Clopper–Pearson 95 % interval (`rate_ci95`)."""
    k, n = int(success.sum()), int(len(success))
    return {"sr": k / n if n else None, "ci95": rate_ci95(k, n), "n": n}


def block_test(d: np.ndarray) -> dict[str, Any]:
    """Mean of per-block differences `d`, its BCa bootstrap 95 % interval and a two-sided sign-flip p."""
    n = len(d)
    out: dict[str, Any] = {"effect": float(d.mean()) if n else None, "ci95": None, "p": None, "n_blocks": n}
    if n < 2:
        return out
    rng = np.random.default_rng(SEED)
    if np.all(d == d[0]):
        out["ci95"] = [float(d[0]), float(d[0])]
    else:
        with warnings.catch_warnings():
            warnings.simplefilter(
                "ignore"
            )  # BCa's degenerate-sample warnings: the percentile ends still hold
            ci = sps.bootstrap((d,), np.mean, n_resamples=N_BOOT, method="BCa", rng=rng).confidence_interval
        out["ci95"] = [float(ci.low), float(ci.high)]
    if not np.any(d):
        out["p"] = 1.0
        return out
    result = sps.permutation_test(
        (d, -d),
        half_mean_difference,
        permutation_type="samples",
        vectorized=True,
        n_resamples=2**n if n <= EXACT_BLOCKS else N_FLIPS,
        alternative="two-sided",
        rng=rng,
    )
    out["p"] = float(result.pvalue)
    return out


def half_mean_difference(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """The sign-flip statistic: (d, −d) paired, a swap flips d's sign; unswapped, mean(d)."""
    return np.mean(x - y, axis=axis) / 2


def no_change_blocks(rows: pd.DataFrame) -> pd.Series:
    """Each block's no-change success, indexed by block, for the blocks that ran the no-change view."""
    base = rows[rows["kind"] == ""].drop_duplicates(BLOCK)
    return base.set_index(BLOCK)["success"].rename("base")


def kind_effects(rows: pd.DataFrame, design: Decomposition) -> dict[str, dict[str, Any]]:
    """Each kind of change's paired effect against the no-change view (module docstring), by its name."""
    base = no_change_blocks(rows)
    out = {}
    for kind in design.kinds:
        sub = rows[rows["kind"] == "+".join(kind)]
        if sub.empty:
            continue
        mean = sub.groupby(BLOCK)["success"].mean()
        both = mean.index.intersection(base.index)
        d = (mean.loc[both] - base.loc[both]).to_numpy(float)
        out[design.kind_name(kind)] = {
            "factors": list(kind),
            **rate(sub["success"]),
            "n_variants": int(sub.drop_duplicates("instance_id").shape[0]),
            **{f"{k}_effect" if k == "ci95" else k: v for k, v in block_test(d).items()},
        }
    return out


def interactions(rows: pd.DataFrame, design: Decomposition) -> dict[str, dict[str, Any]]:
    """S(both) − S(first) − S(second) + S(none) per two-change variant whose parts ran in its block, per block mean."""
    columns = [f.column for f in design.sub_factors]
    by = rows.set_index([*BLOCK, *columns])["success"]
    by = by[~by.index.duplicated()]
    base = no_change_blocks(rows)
    out = {}
    singles = {k for k in design.kinds if len(k) == 1}
    for kind in (k for k in design.kinds if len(k) == 2 and all((c,) in singles for c in k)):
        per_block: dict[tuple, list[float]] = {}
        matched: set[str] = set()
        for r in rows[rows["kind"] == "+".join(kind)].itertuples(index=False):
            block = tuple(getattr(r, c) for c in BLOCK)
            if block not in base.index:
                continue
            parts = []
            for column in kind:
                alone = tuple(
                    getattr(r, f.column) if f.column == column else f.no_change for f in design.sub_factors
                )
                if (*block, *alone) in by.index:
                    parts.append(by.loc[(*block, *alone)])
            if len(parts) == 2:
                per_block.setdefault(block, []).append(r.success - parts[0] - parts[1] + base.loc[block])
                matched.add(r.instance_id)
        d = np.array([np.mean(v) for v in per_block.values()], float)
        out[design.kind_name(kind)] = {
            "factors": list(kind),
            "n_variants": len(matched),
            **{"interaction" if k == "effect" else k: v for k, v in block_test(d).items()},
        }
    return out


def dose_response(rows: pd.DataFrame, factor: SubFactor) -> dict[str, Any] | None:
    """Success against `factor`'s severity over its single-change views and the no-change view (module docstring);
    None where it has no single-change view."""
    sub = rows[rows["kind"].isin(["", factor.column])]
    if sub["kind"].nunique() < 2:
        return None
    x = factor.severity(sub[factor.column].to_numpy())
    y = sub["success"].to_numpy(float)
    out: dict[str, Any] = {
        "factor": factor.column,
        "unit": factor.unit,
        "n": int(len(y)),
        "curve": [{"magnitude": float(m), **rate(pd.Series(y[x == m]))} for m in np.unique(x)],
        "sr_at_0": None,
        "slope": None,
        "half_magnitude": None,
        "half_magnitude_ci95": None,
    }
    groups = pd.factorize(sub["context_id"])[0]
    # All succeeded or all failed: no slope to fit; one block: clustered standard errors need two.
    if y.min() < y.max() and groups.max() >= 1:
        out |= logistic_half(x, y, groups)
    return out


def logistic_half(x: np.ndarray, y: np.ndarray, groups: np.ndarray) -> dict[str, Any]:
    """A logistic GLM of success `y` on severity `x`, errors clustered by `groups`: the fitted success at 0, the slope
    and its p, and the severity where fitted success halves with its delta-method 95 % interval (empty where the fit
    fails; no half where success does not fall)."""
    import statsmodels.api as sm

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fit = sm.GLM(y, sm.add_constant(x), family=sm.families.Binomial()).fit(
                cov_type="cluster", cov_kwds={"groups": groups}
            )
        except (ValueError, np.linalg.LinAlgError):
            return {}
    a, b = (float(v) for v in fit.params)
    out: dict[str, Any] = {
        "sr_at_0": float(1 / (1 + np.exp(-a))),
        "slope": b,
        "slope_p": float(fit.pvalues[1]) if np.isfinite(fit.pvalues[1]) else None,
    }
    if b >= 0 or not np.all(np.isfinite(fit.cov_params())):
        return out

    def half(theta: np.ndarray) -> float:
        p0 = 1 / (1 + np.exp(-theta[0]))
        return float((np.log(p0 / 2 / (1 - p0 / 2)) - theta[0]) / theta[1])

    theta = np.array([a, b])
    m50 = half(theta)
    eps = 1e-6
    grad = np.array([(half(theta + eps * e) - half(theta - eps * e)) / (2 * eps) for e in np.eye(2)])
    se = float(np.sqrt(grad @ np.asarray(fit.cov_params()) @ grad))
    out["half_magnitude"] = m50
    out["half_magnitude_ci95"] = [m50 - Z95 * se, m50 + Z95 * se] if np.isfinite(se) else None
    return out


def is_variant(split: str, design: Decomposition) -> bool:
    """Whether a benchmark split (`<task>_<split>`) holds the external benchmark's own variants."""
    return str(split).removeprefix(f"{design.task}_") in design.variant_splits


def per_variant(rows: pd.DataFrame, design: Decomposition) -> list[dict[str, Any]]:
    """Each external variant's (instance's) rate and paired difference to the no-change view over the blocks both
    ran, where repeats ran."""
    variants = rows[rows["split"].map(lambda s: is_variant(s, design)) & (rows["kind"] != "")]
    if variants.empty or variants.groupby("instance_id").size().max() < 2:
        return []
    base = rows[rows["kind"] == ""]
    out = []
    for _, sub in variants.groupby("instance_id", sort=False):
        value = str(sub["value"].iloc[0])
        paired = control_deltas(base, sub).get(value, {})
        out.append(
            {
                "task": str(sub[design.group_column].iloc[0]),
                "value": value,
                "kind": design.kind_name(tuple(sub["kind"].iloc[0].split("+"))),
                **rate(sub["success"]),
                "delta_control": paired.get("delta_control"),
                "delta_control_ci95": paired.get("delta_control_ci95"),
                "p_control": paired.get("p_control"),
            }
        )
    return out


def totals(variants: pd.DataFrame, design: Decomposition) -> dict[str, Any]:
    """The micro total (every variant episode alike) and the macro one (the groups' mean), each group's rate, and
    how many variants."""
    group = variants[design.group_column].astype(str).str.split("/").str[0]
    per_group = {g: rate(variants.loc[group == g, "success"]) for g in design.groups if (group == g).any()}
    rates = [r["sr"] for r in per_group.values()]
    return {
        design.micro[0]: rate(variants["success"]),
        design.macro[0]: float(np.mean(rates)) if rates else None,
        "per_suite": per_group,
        "n_variants": int(variants.drop_duplicates("instance_id").shape[0]),
    }


def factor_totals(rows: pd.DataFrame, design: Decomposition) -> dict[str, Any]:
    """The factor's number both ways over every external variant run and the no-change view's rate; where the rows
    carry the fairness gate's verdict of every variant (`gate_passed`), the same over those it passes (`fair`) and
    how many it does not (`n_variants_unfair`)."""
    variants = rows[rows["split"].map(lambda s: is_variant(s, design)) & (rows["kind"] != "")]
    out = {
        **totals(variants, design),
        "no_change": rate(rows[rows["kind"] == ""].drop_duplicates(BLOCK)["success"]),
    }
    if GATE_COLUMN in variants and variants[GATE_COLUMN].notna().all():
        fair = variants[variants[GATE_COLUMN].astype(bool)]
        out["fair"] = totals(fair, design)
        out["n_variants_unfair"] = out["n_variants"] - out["fair"]["n_variants"]
    return out


def twin_pairs(rows: pd.DataFrame, design: Decomposition) -> pd.DataFrame:
    """Each twin row beside its original's success (`original`) and split (`original_split`), same block."""
    column = design.twin.column
    no_change = design.sub_factor(column).no_change
    keys = [*BLOCK, *(f.column for f in design.sub_factors if f.column != column)]
    originals = rows[(rows[column] == no_change) & (rows["kind"] != "")].drop_duplicates(keys)
    originals = originals[[*keys, "success", "split"]].rename(
        columns={"success": "original", "split": "original_split"}
    )
    return rows[rows[column] != no_change].merge(originals, on=keys)


def twins(rows: pd.DataFrame, design: Decomposition) -> dict[str, Any] | None:
    """The twins of the external variants: the factor's number both ways over them, against their originals overall
    and per kind (module docstring); None where no twin ran beside its original."""
    pairs = twin_pairs(rows, design)
    external = pairs[pairs["original_split"].map(lambda s: is_variant(s, design))]
    if pairs.empty:
        return None

    def against(sub: pd.DataFrame) -> dict[str, Any]:
        d = (sub["success"] - sub["original"]).groupby([sub[c] for c in BLOCK]).mean().to_numpy(float)
        return {
            "n_variants": int(sub.drop_duplicates("instance_id").shape[0]),
            "sr": float(sub["success"].mean()),
            "sr_original": float(sub["original"].mean()),
            **{"difference" if k == "effect" else k: v for k, v in block_test(d).items()},
        }

    column = design.twin.column
    kinds = {}
    for kind, sub in pairs.groupby("kind", sort=False):
        original = tuple(c for c in kind.split("+") if c != column)
        kinds[design.kind_name(original)] = {"factors": list(original), **against(sub)}
    return {
        "column": column,
        **totals(external, design),
        "against_original": against(external) if not external.empty else None,
        "kinds": kinds,
    }


def compute(episodes: pd.DataFrame, design: Decomposition) -> dict[str, Any] | None:
    """The decomposition of one policy's episodes of `design.task` in the splits it reads; None without any, or
    without its columns."""
    rows = episodes[episodes["task"].astype(str) == design.task] if "task" in episodes else episodes.iloc[:0]
    if "split" in rows:
        rows = rows[rows["split"].map(design.reads)]
    if rows.empty or any(f.column not in rows for f in design.sub_factors):
        return None
    rows = views(rows, design)
    column = design.instruction_column
    return {
        "instruction": sorted(rows[column].astype(str).unique()) if column in rows else [],
        design.name: factor_totals(rows, design),
        "kinds": kind_effects(rows, design),
        "interactions": interactions(rows, design),
        "dose_response": {
            f.name: d for f in design.dose_factors if (d := dose_response(rows, f)) is not None
        },
        "per_variant": per_variant(rows, design),
        **({"twin": twins(rows, design)} if design.twin is not None else {}),
    }
