"""Metrics against small tables computed by hand (docs/formats.md, "Metrics"), plus the add-ons' contracts."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.metrics import (
    EpisodesError,
    MetricsConfig,
    compute_all_metrics,
    compute_metrics,
    conditional_cv,
    interaction_metrics,
    policy_layouts,
    rate_interval,
    split_metrics,
)

pytestmark = pytest.mark.fast

EPS = 1e-6
FAST = MetricsConfig(n_perm=200, n_glm=50, max_perm=200)


def episodes(
    cells: dict[tuple[str, str], list[int]], split: str = "color", factor: str = "color", policy: str = "p"
) -> pd.DataFrame:
    """One instance per (value, context) with the listed outcomes, one row per repeat."""
    rows = [
        {
            "policy": policy,
            "split": split,
            "factor": factor,
            "value": value,
            "context_id": ctx,
            "instance_id": f"{split}/{value}/{ctx}",
            "repeat": r,
            "success": bool(s),
        }
        for (value, ctx), outcomes in cells.items()
        for r, s in enumerate(outcomes)
    ]
    return pd.DataFrame(rows)


# 2 contexts × 3 values × 2 repeats. c1: SR a = 1, b = 0.5, c = 0 (μ 0.5, σ = √(1/6)); c2: all fail.
HAND = episodes(
    {
        ("a", "c1"): [1, 1],
        ("b", "c1"): [1, 0],
        ("c", "c1"): [0, 0],
        ("a", "c2"): [0, 0],
        ("b", "c2"): [0, 0],
        ("c", "c2"): [0, 0],
    }
)


def test_single_split_by_hand():
    m = split_metrics(HAND, FAST)
    assert (m["n_instances"], m["n_episodes"]) == (6, 12)
    assert m["sr"] == pytest.approx(3 / 12)
    # CV(c1) = √(1/6) / (0.5 + ε); CV(c2) = 0 / (0 + ε) = 0; cv = their mean.
    assert m["cv"] == pytest.approx((math.sqrt(1 / 6) / (0.5 + EPS) + 0.0) / 2, rel=1e-12)
    assert m["cv"] == pytest.approx(0.408248, abs=1e-6)
    paper_keys = {v: {k: s[k] for k in ("sr", "n_episodes", "signed_dev")} for v, s in m["per_value"].items()}
    assert paper_keys == {
        "a": {"sr": 0.5, "n_episodes": 4, "signed_dev": pytest.approx(0.25)},  # mean(1 − 0.5, 0 − 0)
        "b": {"sr": 0.25, "n_episodes": 4, "signed_dev": pytest.approx(0.0)},
        "c": {"sr": 0.0, "n_episodes": 4, "signed_dev": pytest.approx(-0.25)},
    }
    # a never fails where others do (odds ratio ∞: undefined, None); c never succeeds (0).
    assert (m["per_value"]["a"]["odds_ratio"], m["per_value"]["c"]["odds_ratio"]) == (None, 0.0)


def test_context_where_everything_fails_has_zero_ccv():
    sr = np.array([1.0, 0.5, 0.0, 0.0, 0.0, 0.0])
    ccv = conditional_cv(sr, np.array([0, 0, 0, 1, 1, 1]), EPS)
    assert ccv == pytest.approx([math.sqrt(1 / 6) / (0.5 + EPS), 0.0])


def test_split_where_everything_fails_has_null_cv():
    m = split_metrics(episodes({(v, c): [0, 0] for v in "abc" for c in ("c1", "c2")}), FAST)
    assert m["sr"] == 0.0
    assert (m["cv"], m["cv_null"], m["cv_excess"], m["p_value"], m["p_value_cv"]) == (None,) * 5
    assert m["n_contexts_all_failed"] == 2
    # The interval stays defined at 0/12: an upper bound on SR, Clopper–Pearson's 1 − 0.025^(1/12).
    assert m["sr_ci95"] == pytest.approx([0.0, 1 - 0.025 ** (1 / 12)], abs=1e-12)


# Factorial 2 × 2 in one context, 2 repeats: SR(a1,b1)=1, SR(a2,b1)=.5, SR(a1,b2)=0, SR(a2,b2)=.5.
FACTORIAL = episodes(
    {("a1|b1", "c*"): [1, 1], ("a2|b1", "c*"): [1, 0], ("a1|b2", "c*"): [0, 0], ("a2|b2", "c*"): [0, 1]},
    split="A_x_B",
    factor="A|B",
)


def test_factorial_cv_and_iec_by_hand():
    m = interaction_metrics(FACTORIAL, FAST)
    # CV(A|b1) = σ(1, .5)/μ = .25/.75 = 1/3;  CV(A|b2) = σ(0, .5)/μ = .25/.25 = 1.
    cv_a = [0.25 / (0.75 + EPS), 0.25 / (0.25 + EPS)]
    # CV(B|a1) = σ(1, 0)/μ = .5/.5 = 1;        CV(B|a2) = σ(.5, .5) = 0.
    cv_b = [0.5 / (0.5 + EPS), 0.0]
    assert m["cv"]["A"] == pytest.approx(np.mean(cv_a), rel=1e-12)  # ≈ 2/3
    assert m["cv"]["B"] == pytest.approx(np.mean(cv_b), rel=1e-12)  # ≈ 1/2
    # IEC(A;B) = σ(1/3, 1) / μ = (1/3)/(2/3) = 0.5;  IEC(B;A) = σ(1, 0)/μ = 0.5/0.5 = 1.
    assert m["iec"]["A|B"] == pytest.approx(np.std(cv_a) / (np.mean(cv_a) + EPS), rel=1e-12)
    assert m["iec"]["A|B"] == pytest.approx(0.5, abs=1e-5)
    assert m["iec"]["B|A"] == pytest.approx(1.0, abs=1e-5)
    assert (m["sr"], m["n_episodes"], m["factors"]) == (0.5, 8, ["A", "B"])
    assert m["per_value"]["a2|b1"] == {"sr": 0.5, "n_episodes": 2}


def test_factorial_all_failed_is_null():
    m = interaction_metrics(FACTORIAL.assign(success=False), FAST)
    assert m["cv"] == {"A": None, "B": None}
    assert m["iec"] == {"A|B": None, "B|A": None}
    assert m["iec_null"] == {"A|B": None, "B|A": None} and m["p_interaction"] is None


def _noisy(seed: int = 0, contexts: int = 3, values: int = 6, repeats: int = 5) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    return episodes(
        {
            (f"v{v}", f"c{c}"): list(rng.random(repeats) < (v + 1) / (values + 1))
            for v in range(values)
            for c in range(contexts)
        }
    )


def test_noise_floor_is_seeded_and_explains_a_flat_table():
    # Every value succeeds 3 times in 5, in different repeats: CV 0, and its noise floor is what
    # reshuffling the values within each repeat shows.
    flat = episodes({(v, "c1"): list(np.roll([1, 1, 1, 0, 0], i)) for i, v in enumerate("abcdef")})
    m = split_metrics(flat, FAST)
    assert m["cv"] == pytest.approx(0.0) and m["cv_excess"] == 0.0
    assert m["cv_null"] > 0.1 and m["p_value_cv"] == 1.0
    lo, hi = m["cv_excess_ci95"]  # no bias seen, and how large one could hide in 6 values × 5 repeats
    assert m["cv_excess"] == 0.0 and lo == 0.0 and 0.0 < hi < 1.0
    table = _noisy()
    first = split_metrics(table, FAST)
    assert split_metrics(table, FAST) == first
    assert split_metrics(table, MetricsConfig(n_perm=200, n_glm=50, seed=1))["cv_null"] != first["cv_null"]


def test_permutations_keep_every_context_and_repeat_block():
    # Under common random numbers a (context, repeat) block's successes stay in that block: repeat 0
    # succeeds for every value and repeat 1 for none, so any shuffle reproduces the table exactly.
    crn = episodes({(v, c): [1, 0] for v in "abcd" for c in ("c1", "c2")})
    m = split_metrics(crn, FAST)
    assert m["cv"] == pytest.approx(0.0) and m["cv_null"] == pytest.approx(0.0)


def test_p_values_small_for_dependence_large_for_none():
    strong = episodes({(v, c): [int(v in "ab")] * 10 for v in "abcd" for c in ("c1", "c2")})
    m = split_metrics(strong, FAST)
    assert m["p_value_cv"] <= 2 / 201 and m["p_value"] < 1e-3
    assert {
        v: s["odds_ratio"] is None or s["q_value"] < 0.05 for v, s in m["per_value"].items()
    } == dict.fromkeys("abcd", True)
    flat = episodes(
        {(v, c): list(np.roll([1, 0] * 5, i)) for i, v in enumerate("abcd") for c in ("c1", "c2")}
    )
    m = split_metrics(flat, FAST)
    assert m["p_value_cv"] == 1.0 and m["p_value"] > 0.99
    assert all(s["odds_ratio"] == pytest.approx(1.0) and s["q_value"] > 0.99 for s in m["per_value"].values())


def test_per_value_odds_ratio_by_hand():
    # One context, 4 repeats (blocks). b against {a, c, d}: r0 all succeed (no information);
    # r1, r2: b 1/1 vs rest 1/3 → ad/n = 2/4, bc/n = 0; r3: b 0/1 vs rest 2/3 → ad/n = 0, bc/n = 2/4.
    # Mantel–Haenszel OR = (0.5 + 0.5) / 0.5 = 2.
    table = episodes(
        {
            ("a", "c"): [1, 0, 0, 0],
            ("b", "c"): [1, 1, 1, 0],
            ("c", "c"): [1, 1, 0, 1],
            ("d", "c"): [1, 0, 1, 1],
        }
    )
    m = split_metrics(table, FAST)
    assert m["per_value"]["b"]["odds_ratio"] == pytest.approx(2.0)
    assert m["per_value"]["a"]["odds_ratio"] == 0.0 and m["per_value"]["a"]["odds_ratio_ci95"] is None
    assert m["n_contexts"] == 1 and m["n_contexts_all_failed"] == 0
    # A value that fails more often than the rest in every block of two contexts: OR < 1, q < 0.05.
    weak = episodes(
        {
            (v, c): list(
                np.roll([1, 0, 0, 0, 1, 0, 0, 0, 1, 0] if v == "a" else [1, 1, 1, 0, 0, 1, 1, 1, 0, 1], i)
            )
            for i, v in enumerate("abcd")
            for c in ("c1", "c2")
        }
    )
    a = split_metrics(weak, FAST)["per_value"]["a"]
    assert a["odds_ratio"] < 0.2 and a["odds_ratio_ci95"][0] < a["odds_ratio"] < a["odds_ratio_ci95"][1] < 1
    assert a["q_value"] < 0.05


def test_factorial_p_values_and_interaction():
    # Success depends on A only: a1 always succeeds, a2 never, at every b.
    cells = {(f"a{a}|b{b}", "c*"): [int(a == 1)] * 8 for a in (1, 2) for b in (1, 2, 3)}
    m = interaction_metrics(episodes(cells, split="A_x_B", factor="A|B"), FAST)
    assert m["p_value_cv"]["A"] <= 2 / 201 and m["p_value"]["A"] <= 1 / 51  # the smallest 50 draws allow
    assert m["p_value_cv"]["B"] == 1.0
    # A pure interaction: a1 succeeds only at b1, a2 only at b2 (no main effect in SR).
    cross = {(f"a{a}|b{b}", "c*"): [int(a == b)] * 8 for a in (1, 2) for b in (1, 2)}
    m = interaction_metrics(episodes(cross, split="A_x_B", factor="A|B"), FAST)
    assert m["p_interaction"] <= 1 / 51  # sparse: parametric bootstrap, the smallest 50 draws allow
    assert m["iec_null"]["A|B"] is not None and m["iec_excess"]["A|B"] >= 0


def test_split_numbers_do_not_depend_on_other_splits():
    alone = compute_metrics(_noisy(), FAST)["splits"]["color"]
    with_other = pd.concat([_noisy(), FACTORIAL])
    assert compute_metrics(with_other, FAST)["splits"]["color"] == alone


def test_layout_and_several_policies():
    both = pd.concat([HAND, _noisy().assign(policy="q")])
    m = compute_all_metrics(both, FAST)
    assert set(m) == {"epsilon", "resampling", "policies", "comparisons"} and set(m["policies"]) == {"p", "q"}
    assert m["policies"]["p"]["splits"]["color"] == compute_metrics(HAND, FAST)["splits"]["color"]
    assert set(policy_layouts(m)) == {"p", "q"}
    single = compute_all_metrics(pd.concat([HAND, FACTORIAL]), FAST)
    assert single["epsilon"] == EPS and single["policy"] == "p"
    assert set(single["splits"]["color"]) >= {
        "factor",
        "n_instances",
        "n_episodes",
        "sr",
        "sr_ci95",
        "cv",
        "cv_null",
        "cv_excess",
        "cv_excess_ci95",
        "p_value",
        "p_value_cv",
        "n_contexts_all_failed",
        "per_value",
    }
    assert set(single["splits"]["color"]["per_value"]["a"]) >= {"odds_ratio", "odds_ratio_ci95", "q_value"}
    assert set(single["interactions"]["A_x_B"]) >= {"iec", "iec_null", "iec_excess", "p_interaction"}
    assert set(single["interactions"]["A_x_B"]["iec"]) == {"A|B", "B|A"}
    color = single["splits"]["color"]
    assert single["average"] == {"sr": 0.25, "cv": color["cv"], "cv_excess": color["cv_excess"]}
    assert policy_layouts(single) == {"p": single}
    with pytest.raises(ValueError, match="one policy"):
        compute_metrics(both, FAST)


def test_bad_tables_name_the_problem():
    with pytest.raises(EpisodesError, match="context_id, success"):
        compute_metrics(HAND.drop(columns=["context_id", "success"]))
    with pytest.raises(EpisodesError, match="success must be boolean"):
        compute_metrics(HAND.assign(success=2))
    with pytest.raises(EpisodesError, match="'color'.*mixes factors"):
        compute_metrics(HAND.assign(factor=["color"] * 11 + ["shape"]))
    with pytest.raises(EpisodesError, match="repeat"):
        compute_metrics(HAND.drop(columns=["repeat"]))
    with pytest.raises(EpisodesError, match="instance 'color/a/c1'"):
        compute_metrics(HAND.assign(context_id=["x"] + list(HAND["context_id"][1:])))
    with pytest.raises(ValueError, match="epsilon"):
        MetricsConfig(epsilon=0)


def test_paper_sized_split():
    rng = np.random.default_rng(0)
    p = rng.random(1551)
    table = episodes({(f"v{i % 141}", f"c{i // 141}"): list(rng.random(5) < p[i]) for i in range(1551)})
    m = split_metrics(table, MetricsConfig(n_glm=20, max_perm=1000))  # 1,000 permutations, 20 GLM refits
    # Success varies per cell (value × context), so both tests see it; none of the 20 GLM refits reaches the
    # statistic, so p comes from the χ² tail stretched over them, below their floor 1/21.
    assert m["n_instances"] == 1551 and m["p_value_cv"] < 0.01
    assert m["p_value"] < 1 / 21 and m["p_value_method"] == "permutation+scaled_chi2_tail"


def test_per_value_p_value_is_exact_where_the_cmh_chi_square_is_not():
    from roboview.eval.statistics.significance import exact_stratified_p

    # A value failing its 2 episodes where 5 of 141 fail per (context, repeat) block: the exact
    # conditional probability is (5/141)²; the asymptotic CMH χ² would say 1.6e-13.
    p = exact_stratified_p(np.array([0, 0]), np.array([1, 1]), np.array([136, 136]), np.array([141, 141]))
    assert p == pytest.approx((5 / 141) ** 2, rel=1e-9)
    # Fisher's exact test is the one-stratum case.
    from scipy.stats import fisher_exact

    table = [[2, 6], [7, 3]]
    assert exact_stratified_p(np.array([2]), np.array([8]), np.array([9]), np.array([18])) == pytest.approx(
        fisher_exact(table).pvalue, rel=1e-9
    )


def test_the_control_arm_is_a_result_field_of_every_split():
    """sr_control: the all-baseline instance of each (context, repeat) a split ran, on the same seed, whichever split
    holds it (a deduplicated benchmark keeps it in one); with its Clopper–Pearson interval."""
    from roboview.variation.factors import baselines

    red, near = baselines()["color"], baselines()["dist_scale"]
    color = episodes(
        {(red, "c1"): [1, 1], (red, "c2"): [1, 0], ("blue", "c1"): [0, 0], ("blue", "c2"): [0, 1]}
    )
    color = color.assign(color=color["value"], dist_scale=near)
    dist = episodes({("3", "c1"): [0, 1]}, split="dist_scale", factor="dist_scale")
    dist = dist.assign(color=red, dist_scale=dist["value"])
    m = compute_metrics(pd.concat([color, dist], ignore_index=True), FAST)
    c, d = m["splits"]["color"], m["splits"]["dist_scale"]
    assert (c["sr_control"], c["n_control_episodes"]) == (0.75, 4)
    assert c["sr_control_ci95"] == pytest.approx(list(rate_interval(3, 4)))
    assert c["sr_control_ci95"] == pytest.approx([0.1941, 0.975**0.25], abs=1e-4)
    # dist_scale ran c1's two repeats: its control arm is red's c1 episodes, taken from the color split.
    assert (d["sr_control"], d["n_control_episodes"]) == (1.0, 2)
    # Each value's paired difference to the control arm on the same (context, repeat) seeds, McNemar-tested:
    # blue fails 3 of the 4 pairs red succeeds in and succeeds in the one red fails (exact p = 2 · 5/16).
    blue = c["per_value"]["blue"]
    assert (blue["delta_control"], blue["n_control_pairs"]) == (-0.5, 4)
    assert blue["p_control"] == pytest.approx(0.625)
    # Its paired interval: 1 pair blue alone succeeds in, 3 red alone does, so φ = −1 and the interval is the Wilson
    # limits' differences, [l(1/4) − u(3/4), u(1/4) − l(3/4)] (tests/eval/statistics/test_rate_intervals.py).
    assert blue["delta_control_ci95"] == pytest.approx([-0.9088, 0.3987], abs=1e-4)
    assert (c["per_value"][red]["delta_control"], c["per_value"][red]["p_control"]) == (0.0, 1.0)
    assert (d["per_value"]["3"]["delta_control"], d["per_value"]["3"]["n_control_pairs"]) == (-0.5, 2)
    assert d["per_value"]["3"]["delta_control_ci95"] == pytest.approx([-0.9055, 0.2726], abs=1e-4)
    flat = compute_metrics(HAND, FAST)["splits"]["color"]  # no factor columns: no control arm to read
    assert (flat["sr_control"], flat["n_control_episodes"]) == (None, 0)
    assert not any("delta_control" in v for v in flat["per_value"].values())
