"""LIBERO-plus's camera number, taken apart: the `liberoplus` task's analysis in metrics.json and the report.

From one policy's episodes of a `liberoplus_camera*` benchmark (the `liberoplus` task's rows):

- **The camera number** two ways: as LIBERO-plus's README totals it (every variant episode weighted alike, so a
  suite with more variants weighs more) and as vla-eval's results average it (each suite's rate over its own
  variants, then the four suites' mean). Beside it, the no-change view's rate.
- **Each kind of change against the no-change view**, paired by block (the same task, init state and seed):
  azimuth alone, elevation alone, scale alone, rotation z alone, rotation y alone, and LIBERO-plus's two-change
  kinds. Per block, the kind's mean success minus the no-change episode's; the effect is the mean over blocks,
  its 95 % interval a bootstrap over blocks (scipy `bootstrap`, BCa), its p a sign-flip permutation test over
  blocks (scipy `permutation_test`: exact up to 16 blocks, 100,000 random flips beyond). Blocks, not episodes,
  are the independent units: one no-change episode pairs with every variant of its block.
- **Interaction**: for each two-change variant whose single-change parts ran in its block, S(both) − S(first) −
  S(second) + S(none) — 0 when the two costs add on the success scale, negative when together they cost more.
  Averaged per block, tested and bounded as above.
- **Dose–response** over azimuth magnitude (|azimuth| in degrees, the azimuth-only views with the no-change view at
  0) and over scale (percent above 100): a logistic GLM (statsmodels) of success on magnitude with standard errors
  clustered by task, the fitted success at 0, and the magnitude at which the fitted success falls to half of it,
  with a delta-method 95 % interval (None where success does not fall with magnitude).
- **Per variant**, where repeats ran (init states 0, 1, …): its rate with a Clopper–Pearson interval, its paired
  difference to the no-change view over the same init states and McNemar's exact test.

Every number is validated against known truth by simulation (tests/libero/test_plus_decomposition.py).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from roboview.libero.plus import LIBERO_PLUS_SPLITS, NO_CHANGE, SHORT, SUB_FACTORS, SUITES

# The episode column with the fairness gate's verdict of the instance (roboview.benchmark.format.GATE_COLUMN, which
# this wing's floor may not import).
GATE_COLUMN = "gate_passed"

KEY = "liberoplus_camera"
TITLE = "LIBERO-plus's camera dimension, taken apart"
N_BOOT = 2000
N_FLIPS = 100_000
EXACT_BLOCKS = 16  # 2**16 sign flips: enumerated exactly
SEED = 0
KINDS = (
    ("view_azimuth",),
    ("view_elevation",),
    ("view_scale",),
    ("view_rotz",),
    ("view_roty",),
    ("view_azimuth", "view_elevation"),
    ("view_rotz", "view_roty"),
)


def kind_name(kind: tuple[str, ...]) -> str:
    return " + ".join(SHORT[f] for f in kind)


def _views(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows with integer sub-factor columns and `kind` (what the view changes, "+"-joined factor names)."""
    params = {f: rows[f].astype(int) for f in SUB_FACTORS}
    kind = pd.Series("", index=rows.index)
    for f, b in zip(SUB_FACTORS, NO_CHANGE):
        kind = kind.where(params[f] == b, kind + "+" + f)
    kind = kind.str.lstrip("+")
    return rows.assign(**params, kind=kind, success=rows["success"].astype(int))


def _rate(success: pd.Series) -> dict[str, Any]:
    """The success rate with its Clopper–Pearson 95 % interval (statsmodels)."""
    from statsmodels.stats.proportion import proportion_confint

    k, n = int(success.sum()), int(len(success))
    # Clopper–Pearson ("beta"), the interval roboview.eval.statistics.tables.rate_interval gives every other success
    # rate (this wing may not import roboview.eval): it covers ≥ 95 % at every rate, near 1 too (docs/statistics.md).
    ci = [float(x) for x in proportion_confint(k, n, alpha=0.05, method="beta")] if n else None
    return {"sr": k / n if n else None, "ci95": ci, "n": n}


def _mcnemar_exact(a: np.ndarray, b: np.ndarray) -> float:
    """McNemar's exact test on paired outcomes (statsmodels); 1.0 when no pair disagrees."""
    from statsmodels.stats.contingency_tables import mcnemar

    table = [[np.sum(a & b), np.sum(a & ~b)], [np.sum(~a & b), np.sum(~a & ~b)]]
    return 1.0 if table[0][1] + table[1][0] == 0 else float(mcnemar(table, exact=True).pvalue)


def _block_test(d: np.ndarray) -> dict[str, Any]:
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
    flips = 2**n if n <= EXACT_BLOCKS else N_FLIPS
    result = sps.permutation_test(
        (d, -d),
        _half_mean_difference,
        permutation_type="samples",
        vectorized=True,
        n_resamples=flips,
        alternative="two-sided",
        rng=rng,
    )
    out["p"] = float(result.pvalue)
    return out


def _half_mean_difference(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x - y, axis=axis) / 2  # (d, −d) paired: a swap flips d's sign; unswapped, mean(d)


def _blocks(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per block (context_id, repeat) with its no-change success, for blocks that ran the no-change view."""
    base = rows[rows["kind"] == ""].drop_duplicates(["context_id", "repeat"])
    return base.set_index(["context_id", "repeat"])["success"].rename("base")


def kind_effects(rows: pd.DataFrame) -> dict[str, dict[str, Any]]:
    """Each kind of change's paired effect against the no-change view (module docstring)."""
    base = _blocks(rows)
    out = {}
    for kind in KINDS:
        sub = rows[rows["kind"] == "+".join(kind)]
        if sub.empty:
            continue
        mean = sub.groupby(["context_id", "repeat"])["success"].mean()
        both = mean.index.intersection(base.index)
        d = (mean.loc[both] - base.loc[both]).to_numpy(float)
        out[kind_name(kind)] = {
            "factors": list(kind),
            **_rate(sub["success"]),
            "n_variants": int(sub.drop_duplicates("instance_id").shape[0]),
            **{f"{k}_effect" if k == "ci95" else k: v for k, v in _block_test(d).items()},
        }
    return out


def interactions(rows: pd.DataFrame) -> dict[str, dict[str, Any]]:
    """S(both) − S(first) − S(second) + S(none) per two-change variant whose parts ran in its block, per block mean."""
    by = rows.set_index(["context_id", "repeat", *SUB_FACTORS])["success"]
    by = by[~by.index.duplicated()]
    base = _blocks(rows)
    out = {}
    for kind in KINDS:
        if len(kind) != 2:
            continue
        sub = rows[rows["kind"] == "+".join(kind)]
        per_block: dict[tuple, list[float]] = {}
        matched: set[str] = set()
        for r in sub.itertuples(index=False):
            block = (r.context_id, r.repeat)
            if block not in base.index:
                continue
            params = {f: getattr(r, f) for f in SUB_FACTORS}
            parts = []
            for f in kind:
                alone = tuple(params[g] if g == f else b for g, b in zip(SUB_FACTORS, NO_CHANGE))
                key = (*block, *alone)
                if key in by.index:
                    parts.append(by.loc[key])
            if len(parts) == 2:
                per_block.setdefault(block, []).append(r.success - parts[0] - parts[1] + base.loc[block])
                matched.add(r.instance_id)
        d = np.array([np.mean(v) for v in per_block.values()], float)
        out[kind_name(kind)] = {
            "factors": list(kind),
            "n_variants": len(matched),
            **{"interaction" if k == "effect" else k: v for k, v in _block_test(d).items()},
        }
    return out


def _magnitude(rows: pd.DataFrame, factor: str) -> pd.Series:
    if factor == "view_azimuth":
        az = rows[factor]
        return np.minimum(az, 360 - az).astype(float)
    return (rows[factor] - 100).astype(float)


def dose_response(rows: pd.DataFrame, factor: str) -> dict[str, Any] | None:
    """Success against `factor`'s magnitude over its single-change views and the no-change view (module docstring)."""
    import statsmodels.api as sm

    sub = rows[rows["kind"].isin(["", factor])]
    if sub["kind"].nunique() < 2:
        return None
    x = _magnitude(sub, factor).to_numpy()
    y = sub["success"].to_numpy(float)
    curve = [{"magnitude": float(m), **_rate(pd.Series(y[x == m]))} for m in np.unique(x)]
    out: dict[str, Any] = {
        "factor": factor,
        "unit": "degrees" if factor == "view_azimuth" else "percent above 100",
        "n": int(len(y)),
        "curve": curve,
        "sr_at_0": None,
        "slope": None,
        "half_magnitude": None,
        "half_magnitude_ci95": None,
    }
    if y.min() == y.max():
        return out  # all succeeded or all failed: no slope to fit
    groups = pd.factorize(sub["context_id"])[0]
    if groups.max() < 1:
        return out  # one block: clustered standard errors need two (one task from one init state has no slope's error)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fit = sm.GLM(y, sm.add_constant(x), family=sm.families.Binomial()).fit(
                cov_type="cluster", cov_kwds={"groups": groups}
            )
        except (ValueError, np.linalg.LinAlgError):
            return out
    a, b = (float(v) for v in fit.params)
    out["sr_at_0"] = float(1 / (1 + np.exp(-a)))
    out["slope"] = b
    out["slope_p"] = float(fit.pvalues[1]) if np.isfinite(fit.pvalues[1]) else None
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
    out["half_magnitude_ci95"] = [m50 - 1.959964 * se, m50 + 1.959964 * se] if np.isfinite(se) else None
    return out


def per_variant(rows: pd.DataFrame) -> list[dict[str, Any]]:
    """Each LIBERO-plus variant's rate and paired difference to the no-change view, where repeats ran."""

    variants = rows[rows["split"].map(_is_liberoplus) & (rows["kind"] != "")]
    if variants.empty or variants.groupby("instance_id").size().max() < 2:
        return []
    base = _blocks(rows)
    out = []
    for (task, value), sub in variants.groupby(["liberoplus_task", "value"], sort=False):
        joined = sub.set_index(["context_id", "repeat"])["success"]
        both = joined.index.intersection(base.index)
        a, b = joined.loc[both].to_numpy(bool), base.loc[both].to_numpy(bool)
        out.append(
            {
                "task": str(task),
                "value": str(value),
                "kind": kind_name(tuple(sub["kind"].iloc[0].split("+"))),
                **_rate(sub["success"]),
                "delta_control": float(a.mean() - b.mean()) if len(both) else None,
                "p_control": _mcnemar_exact(a, b) if len(both) else None,
            }
        )
    return out


def _is_liberoplus(split: str) -> bool:
    return str(split).removeprefix("liberoplus_") in LIBERO_PLUS_SPLITS


def _totals(variants: pd.DataFrame) -> dict[str, Any]:
    """Micro (every variant episode alike: LIBERO-plus's README) and macro (the suites' mean: vla-eval's) totals."""
    suite = variants["liberoplus_task"].astype(str).str.split("/").str[0]
    per_suite = {s: _rate(variants.loc[suite == s, "success"]) for s in SUITES if (suite == s).any()}
    rates = [r["sr"] for r in per_suite.values()]
    return {
        "liberoplus": _rate(variants["success"]),
        "vla_eval": float(np.mean(rates)) if rates else None,
        "per_suite": per_suite,
        "n_variants": int(variants.drop_duplicates("instance_id").shape[0]),
    }


def camera_number(rows: pd.DataFrame) -> dict[str, Any]:
    """The camera dimension's success rate as LIBERO-plus totals it and as vla-eval averages it, over every variant
    run; and, where the benchmark kept LIBERO-plus's set whatever the fairness gate said (its rows carry the gate's
    verdict, `gate_passed`), the same over the variants the gate passes (`fair`) and how many it does not."""
    variants = rows[rows["split"].map(_is_liberoplus) & (rows["kind"] != "")]
    out = {
        **_totals(variants),
        "no_change": _rate(rows[rows["kind"] == ""].drop_duplicates(["context_id", "repeat"])["success"]),
    }
    if GATE_COLUMN in variants and variants[GATE_COLUMN].notna().all():
        fair = variants[variants[GATE_COLUMN].astype(bool)]
        out["fair"] = _totals(fair)
        out["n_variants_unfair"] = out["n_variants"] - out["fair"]["n_variants"]
    return out


def compute(episodes: pd.DataFrame) -> dict[str, Any] | None:
    """The analysis of one policy's `liberoplus` episodes (certified, counted); None without any."""
    rows = episodes[episodes["task"].astype(str) == "liberoplus"]
    if rows.empty or any(f not in rows for f in SUB_FACTORS):
        return None
    rows = _views(rows)
    instruction = sorted(rows["liberoplus_instruction"].astype(str).unique())
    return {
        "instruction": instruction,
        "camera": camera_number(rows),
        "kinds": kind_effects(rows),
        "interactions": interactions(rows),
        "dose_response": {
            SHORT[f]: d for f in ("view_azimuth", "view_scale") if (d := dose_response(rows, f)) is not None
        },
        "per_variant": per_variant(rows),
    }


# The report half (report.md's lines, the dose-response figure) lives beside it.
from roboview.libero.decomposition_report import FIGURE, markdown, plot  # noqa: E402, F401
