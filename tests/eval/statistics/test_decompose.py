"""The factor decomposition (roboview.eval.statistics.decompose) on the package's conventions, and the design a wing
registers read back through the task registry: every rate's interval is `rate_interval`'s (Clopper–Pearson), the
paired test against the no-change view is `paired_success_test`'s McNemar (statsmodels; exact below 25 discordant
pairs, checked against scipy's binomial test), and every sub-factor, kind and dose factor of LIBERO-plus's registered
design comes out of a small synthetic table."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.stats.contingency_tables import mcnemar

from roboview.eval.reporting.decomposition import markdown
from roboview.eval.statistics import decompose
from roboview.eval.statistics.analyses import task_analyses
from roboview.eval.statistics.tables import rate_interval
from roboview.tasks import load_task
from roboview.tasks.base import analysis_designs
from roboview.tasks.decomposition import Decomposition, SubFactor

pytestmark = pytest.mark.fast


@pytest.fixture(autouse=True)
def fewer_resamples(monkeypatch):
    monkeypatch.setattr(decompose, "N_BOOT", 200)


@pytest.fixture(scope="module")
def design() -> Decomposition:
    return next(d for d in load_task("liberoplus").analyses if d.key == "liberoplus_camera")


def episode(
    design: Decomposition, changes: dict[str, int], success: bool, block: int, repeat: int = 0
) -> dict:
    """One episode row of `design.task`: its sub-factors at the no-change values but `changes`."""
    group = design.groups[block % len(design.groups)]
    values = {f.column: changes.get(f.column, f.no_change) for f in design.sub_factors}
    changed = [c for c, v in values.items() if v != design.sub_factor(c).no_change]
    return {
        "task": design.task,
        "split": f"{design.task}_{'_x_'.join(changed) or design.variant_splits[0]}",
        "success": bool(success),
        design.group_column: f"{group}/{block}",
        design.instruction_column: design.instructions[-1][0],
        "context_id": f"c{block}",
        "repeat": repeat,
        "instance_id": f"{group}/{block}:{sorted(values.items())}",
        "value": "|".join(str(values[c]) for c in changed) or "0",
        **{c: str(v) for c, v in values.items()},
    }


def synthetic(design: Decomposition, n_blocks: int = 6, seed: int = 0) -> pd.DataFrame:
    """Each block: the no-change view, each kind's variant at two severities, and every single-change part of them."""
    rng = np.random.default_rng(seed)
    views: set[tuple[tuple[str, int], ...]] = set()
    for kind in design.kinds:
        for step in (1, 2):
            change = {c: design.sub_factor(c).no_change + 10 * step for c in kind}
            views |= {tuple(sorted(change.items()))} | {((c, v),) for c, v in change.items()}
    rows = []
    for block in range(n_blocks):
        rows.append(episode(design, {}, rng.random() < 0.9, block))
        for view in sorted(views):
            severity = sum(v - design.sub_factor(c).no_change for c, v in view)
            rows.append(episode(design, dict(view), rng.random() < 0.9 - severity / 100, block))
    return pd.DataFrame(rows)


def test_the_wing_registers_its_design_and_the_report_reads_it_from_the_registry(design):
    assert analysis_designs()[design.key] is design
    assert design.key == "liberoplus_camera" and design.name == "camera"
    assert [f.name for f in design.sub_factors] == [
        "azimuth",
        "elevation",
        "scale",
        "rotation z",
        "rotation y",
    ]
    assert [f.name for f in design.dose_factors] == ["azimuth", "scale"]
    episodes = synthetic(design)
    assert task_analyses(episodes)[design.key] == decompose.compute(episodes, design)


def test_every_sub_factor_kind_and_dose_factor_of_the_design_comes_out(design):
    result = decompose.compute(synthetic(design), design)
    assert list(result["kinds"]) == [design.kind_name(k) for k in design.kinds]
    assert {c for k in result["kinds"].values() for c in k["factors"]} == {
        f.column for f in design.sub_factors
    }
    assert all(k["n_blocks"] == 6 and k["n_variants"] == 12 for k in result["kinds"].values())
    pairs = [design.kind_name(k) for k in design.kinds if len(k) == 2]
    assert list(result["interactions"]) == pairs
    assert all(result["interactions"][p]["n_variants"] == 12 for p in pairs)
    assert list(result["dose_response"]) == [f.name for f in design.dose_factors]
    # The no-change view and severities 10 and 20 (azimuth's +10 and +20 degrees; scale's 110 and 120 percent).
    for d in result["dose_response"].values():
        assert [c["magnitude"] for c in d["curve"]] == [0.0, 10.0, 20.0] and d["n"] == 6 * 3
    totals = result[design.name]
    variants = synthetic(design)
    variants = variants[variants["split"].map(lambda s: decompose.is_variant(s, design))]
    assert totals[design.micro[0]]["n"] == int((variants["value"] != "0").sum())
    assert set(totals["per_suite"]) == set(design.groups)
    text = "\n".join(markdown(result, "policy", design))
    assert all(f"| {name} |" in text for name in result["kinds"])
    assert all(f"Dose–response over {name} " in text for name in result["dose_response"])


def rates_in(result) -> list[dict]:
    """Every {sr, ci95, n} rate anywhere in a result."""
    if isinstance(result, dict):
        found = [result] if {"sr", "ci95", "n"} <= set(result) else []
        return found + [r for v in result.values() for r in rates_in(v)]
    if isinstance(result, list):
        return [r for v in result for r in rates_in(v)]
    return []


def test_every_interval_is_rate_interval(design):
    assert decompose.rate(pd.Series([1] * 8 + [0] * 2))["ci95"] == pytest.approx([0.444, 0.975], abs=5e-4)
    episodes = synthetic(design)
    episodes = pd.concat([episodes.assign(repeat=r) for r in range(2)], ignore_index=True)
    result = decompose.compute(episodes, design)
    rates = rates_in(result)
    assert len(rates) > 50 and len(result["per_variant"]) == 6 * 8
    for r in rates:
        k = round(r["sr"] * r["n"])
        assert r["ci95"] == pytest.approx(list(rate_interval(k, r["n"])), abs=1e-12)


def paired_rows(
    design: Decomposition, both: int, variant_only: int, base_only: int, neither: int
) -> pd.DataFrame:
    """One context run over as many repeats as pairs: the no-change view and one LIBERO-plus variant on each."""
    outcomes = [(1, 1)] * both + [(1, 0)] * variant_only + [(0, 1)] * base_only + [(0, 0)] * neither
    column = design.kinds[0][0]
    change = {column: design.sub_factor(column).no_change + 30}
    rows = []
    for r, (v, b) in enumerate(outcomes):
        rows += [episode(design, {}, b, 0, repeat=r), episode(design, change, v, 0, repeat=r)]
    return pd.DataFrame(rows)


def test_the_per_variant_p_is_the_packages_mcnemar(design):
    # 7 discordant pairs (1 against 6): exact, as statsmodels' exact McNemar and scipy's binomial test give it.
    [variant] = decompose.compute(paired_rows(design, 3, 1, 6, 2), design)["per_variant"]
    exact = mcnemar([[3, 1], [6, 2]], exact=True).pvalue
    assert (
        variant["p_control"] == pytest.approx(exact) == pytest.approx(stats.binomtest(1, 7).pvalue) == 0.125
    )
    assert variant["delta_control"] == pytest.approx((4 - 9) / 12) and variant["n"] == 12
    # 26 discordant pairs (8 against 18): χ² with the continuity correction, as every other McNemar p of the
    # package (roboview.eval.statistics.significance.paired_success_test): 0.0776, where the exact test gives 0.0755.
    [variant] = decompose.compute(paired_rows(design, 10, 8, 18, 4), design)["per_variant"]
    table = [[10, 8], [18, 4]]
    assert variant["p_control"] == pytest.approx(mcnemar(table, exact=False, correction=True).pvalue)
    assert variant["p_control"] == pytest.approx(0.07756, abs=1e-5)
    assert mcnemar(table, exact=True).pvalue == pytest.approx(0.07552, abs=1e-5)
    lo, hi = variant["delta_control_ci95"]
    assert lo < (8 - 18) / 40 < hi


def test_a_severity_over_a_period_goes_the_shorter_way_round():
    tilt = SubFactor("tilt", "tilt", 0, period=360, unit="degrees")
    assert list(tilt.severity([0, 10, 350, 180, 190])) == [0.0, 10.0, 10.0, 180.0, 170.0]
    zoom = SubFactor("zoom", "zoom", 100, unit="percent")
    assert list(zoom.severity([100, 150, 80])) == [0.0, 50.0, -20.0]
    toy = dict(
        key="k", title="t", task="toy", name="view", sub_factors=(tilt, zoom), variant_splits=("tilt",),
        group_column="toy_context", groups=("a",), groups_word="groups", source="S", micro=("s", "as S totals it"),
        macro=("m", "as M averages it"),
    )  # fmt: skip
    assert (
        Decomposition(**toy, kinds=(("tilt",), ("tilt", "zoom"))).kind_name(("tilt", "zoom")) == "tilt + zoom"
    )
    with pytest.raises(ValueError, match="roll"):
        Decomposition(**toy, kinds=(("roll",),))
    with pytest.raises(ValueError, match="twice"):
        Decomposition(**{**toy, "sub_factors": (tilt, tilt)}, kinds=())


def test_a_toy_design_decomposes_a_task_of_its_own():
    tilt = SubFactor("tilt", "tilt", 0, period=360, unit="degrees", axis="|tilt| (degrees)")
    design = Decomposition(
        key="toy_view",
        title="A toy view, taken apart",
        task="toy",
        name="view",
        sub_factors=(tilt, SubFactor("zoom", "zoom", 100)),
        kinds=(("tilt",), ("zoom",), ("tilt", "zoom")),
        variant_splits=("tilt_x_zoom",),
        group_column="toy_context",
        groups=("left", "right"),
        groups_word="sides",
        source="Toy",
        micro=("toy", "as Toy totals it"),
        macro=("sides", "as the sides average it"),
    )
    rows = []
    for block, (tilt_value, zoom_value) in enumerate(itertools.product((0, 20, 340), (100, 120))):
        for b in range(4):
            context = f"{('left', 'right')[b % 2]}/{b}"
            changed = [n for n, v, base in (("tilt", tilt_value, 0), ("zoom", zoom_value, 100)) if v != base]
            rows.append(
                {
                    "task": "toy", "split": f"toy_{'_x_'.join(changed) or 'tilt'}", "success": (block + b) % 3 > 0,
                    "toy_context": context, "context_id": context, "repeat": 0, "value": str((tilt_value, zoom_value)),
                    "instance_id": f"{context}:{tilt_value}:{zoom_value}", "tilt": tilt_value, "zoom": zoom_value,
                }
            )  # fmt: skip
    result = decompose.compute(pd.DataFrame(rows), design)
    assert list(result["kinds"]) == ["tilt", "zoom", "tilt + zoom"] and result["instruction"] == []
    # 20 and 340 degrees are both 20 from the no-change view.
    assert [c["magnitude"] for c in result["dose_response"]["tilt"]["curve"]] == [0.0, 20.0]
    assert result["view"]["toy"]["n"] == 8 and set(result["view"]["per_suite"]) == {"left", "right"}
    assert "View success rate over Toy's 8 variants run" in "\n".join(markdown(result, "p", design))
