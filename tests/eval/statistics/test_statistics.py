"""The statistics validated by simulation against known truth (synthetic tables; no simulator).

Tables come from `roboview.eval.statistics.simulate` (a policy with logit-SD τ bias; τ = 0 is none). Tolerances are binomial: with N simulated tables a
rejection rate at level 0.05 has standard error √(0.05·0.95/N).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.metrics import MetricsConfig, interaction_metrics, split_metrics
from roboview.eval.statistics.significance import lrt_power, repeats_needed
from roboview.eval.statistics.simulate import simulate_additive_factorial, simulate_split
from roboview.tasks import load_preset
from roboview.variation.instances import episode_seed, generate_suite

pytestmark = pytest.mark.fast

SIM = MetricsConfig(n_perm=100, n_glm=40, max_perm=100, n_boot=0)  # fixed-B: what these simulations study


def run_many(n_sims: int, seed: int, **design) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n_sims):
        table, true_cv = simulate_split(rng, **design)
        m = split_metrics(table, SIM)
        qs = [s["q_value"] for s in m["per_value"].values() if s["q_value"] is not None]
        rows.append(
            {
                "p": m["p_value"],
                "p_cv": m["p_value_cv"],
                "cv": m["cv"],
                "cv_excess": m["cv_excess"],
                "true_cv": true_cv,
                "min_q": min(qs, default=1.0),
                "method": m["p_value_method"],
            }
        )
    return pd.DataFrame(rows)


def within_binomial(rate: float, level: float, n: int, z: float = 3.0) -> bool:
    return rate <= level + z * math.sqrt(level * (1 - level) / n)


@pytest.fixture(scope="module")
def null_dense() -> pd.DataFrame:
    # 6 values × 3 contexts × 20 repeats at SR 0.5: expected counts ≥ 10, the χ² regime.
    return run_many(200, 1, n_values=6, n_contexts=3, repeats=20, tau=0.0, sr=0.5)


@pytest.fixture(scope="module")
def null_sparse() -> pd.DataFrame:
    # 6 values × 3 contexts × 4 repeats at SR 0.8: the benchmark's usual sparse table (permutation).
    return run_many(150, 2, n_values=6, n_contexts=3, repeats=4, tau=0.0, sr=0.8)


def test_type_one_error_of_p_value_is_nominal(null_dense, null_sparse):
    assert set(null_dense["method"]) == {"asymptotic"}
    assert set(null_sparse["method"]) <= {"permutation", "permutation+scaled_chi2_tail"}
    for sims in (null_dense, null_sparse):
        rate = float(np.mean(sims["p"] < 0.05))
        assert within_binomial(rate, 0.05, len(sims)), rate
        assert rate > 0.0  # a test that never rejects is not calibrated either
    # Below the permutations' floor (1/41 here) the stretched χ² tail decides: still no more rejections than α.
    assert within_binomial(float(np.mean(null_sparse["p"] < 0.01)), 0.01, len(null_sparse))


def test_q_values_control_false_discoveries_under_no_bias(null_dense, null_sparse):
    # Under the complete null every discovery is false: P(any q < 0.05) ≤ 0.05 (BH controls FWER here).
    for sims in (null_dense, null_sparse):
        assert within_binomial(float(np.mean(sims["min_q"] < 0.05)), 0.05, len(sims))


def test_glm_lrt_is_more_powerful_than_the_cv_permutation_test():
    # τ = 0.6 over 9 values × 4 contexts × 5 repeats (sparse, so the GLM is permutation-calibrated).
    sims = run_many(80, 3, n_values=9, n_contexts=4, repeats=5, tau=0.6, sr=0.7)
    glm, cv = float(np.mean(sims["p"] < 0.05)), float(np.mean(sims["p_cv"] < 0.05))
    assert glm >= cv + 0.12, (glm, cv)


@pytest.mark.parametrize("tau", [0.0, 0.6])
def test_cv_excess_tracks_the_noise_free_cv_where_raw_cv_does_not(tau):
    sims = run_many(40, 4, n_values=9, n_contexts=4, repeats=5, tau=tau, sr=0.7)
    truth = sims["true_cv"].mean()
    assert sims["cv"].mean() - truth > 0.1  # the paper's CV sits far above the truth: noise
    assert abs(sims["cv_excess"].mean() - truth) < 0.06
    assert abs(sims["cv_excess"].mean() - truth) < (sims["cv"].mean() - truth) / 2


def test_interaction_calibrated_under_an_additive_truth():
    """A strong main effect of B and no interaction: raw IEC(A; B) is large, iec_excess ≈ 0 and
    p_interaction is uniform (rejection rate at 0.05 within binomial tolerance)."""
    rng = np.random.default_rng(5)
    rejections, iec, excess = [], [], []
    n_sims = 60
    for _ in range(n_sims):
        table = simulate_additive_factorial(rng, n_a=4, n_b=6, repeats=10, tau_a=0.3, b_range=1.5, sr=0.62)
        m = interaction_metrics(table, SIM)
        rejections.append(m["p_interaction"] < 0.05)
        iec.append(m["iec"]["A|B"])
        excess.append(m["iec_excess"]["A|B"])
    assert within_binomial(float(np.mean(rejections)), 0.05, n_sims)
    assert np.mean(iec) > 0.2  # the paper's IEC reads "coupling" into an additive world
    assert np.mean(excess) < np.mean(iec) / 3


def test_power_formula_matches_simulation():
    # 9 values × 4 contexts × 10 repeats at SR 0.5, τ = 0.6: the χ² regime, where the formula applies.
    predicted = lrt_power(9, 4, 10, 0.6, 0.5)
    sims = run_many(60, 6, n_values=9, n_contexts=4, repeats=10, tau=0.6, sr=0.5)
    assert abs(float(np.mean(sims["p"] < 0.05)) - predicted) < 0.12, predicted
    # The paper's layouts at τ = 0.3: more values need fewer repeats (141 colors: 2; 21 poses: 6; 9 Euler steps: 12).
    assert [repeats_needed(v, 11, 0.3, 0.7) for v in (141, 21, 9)] == [2, 6, 12]


def test_common_random_numbers_share_seeds_across_values_and_splits():
    suite = generate_suite(load_preset("tiny"))
    by_context: dict[str, set[int]] = {}
    for instance in suite:
        by_context.setdefault(instance.context_id, set()).add(instance.seed)
    assert all(len(seeds) == 1 for seeds in by_context.values())  # every value, every split
    splits = {i.split for i in suite if i.context_id == suite[0].context_id}
    assert len(splits) >= 4
    context = suite[0].context_id
    assert suite[0].seed == episode_seed(context, 0) != episode_seed(context, 1)
    assert len({i.context_id for i in suite}) >= 3 and len({i.seed for i in suite}) == len(
        {i.context_id for i in suite}
    )


def test_plan_cli_prints_repeats_per_split(capsys):
    from roboview.pipelines.plan import main

    plans = {(p.split, p.factor): p for p in main(["--preset=paper", "--tau=0.3", "--sr=0.7"])}
    assert plans[("color", "color")].n_values == 141 and plans[("color", "color")].n_strata == 11
    assert plans[("color", "color")].repeats == 2 and plans[("camera_pose", "camera_pose")].repeats == 6
    # The factorial split is planned per factor, its strata being (other value, context).
    assert plans[("color_x_camera_pose", "color")].n_strata == 21
    assert "--eval.split_repeats=color=2,camera_pose=6" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--preset=huge"])
    assert "unknown preset 'huge'" in capsys.readouterr().err


def test_paired_comparison_of_two_policies():
    from roboview.eval.statistics.compare import compare_policies

    table, _ = simulate_split(np.random.default_rng(7), n_values=6, n_contexts=8, repeats=5, tau=0.0, sr=0.99)
    a = table.assign(policy="a", success=True)
    same = compare_policies(pd.concat([a, a.assign(policy="b")]), SIM)[0]
    assert (same["delta_sr"], same["p_sr"], same["delta_cv_excess"], same["p_cv_excess"]) == (
        0.0,
        1.0,
        0.0,
        1.0,
    )
    # b fails value v0 in every context and repeat (40 of 240 pairs, all discordant one way).
    b = a.assign(policy="b", success=a["value"] != "v0")
    diff = compare_policies(pd.concat([a, b]), SIM)[0]
    assert diff["n_pairs"] == 240 and diff["delta_sr"] == pytest.approx(-40 / 240)
    # McNemar, χ² with continuity correction at 40 discordant pairs: (|40 − 0| − 1)² / 40.
    from scipy.stats import chi2

    assert diff["p_sr"] == pytest.approx(chi2.sf(39**2 / 40, 1))
    # Swapping whole instances puts all 8 of v0's on one side with probability 2/256: p can reach it.
    assert diff["delta_cv_excess"] > 0.3 and diff["p_cv_excess"] < 0.05
    # One repeat: one episode per cell leaves cv_excess undefined for both, so no cv verdict can come from
    # floating-point residue (SR is still compared).
    first = pd.concat([a, b])
    single = compare_policies(first[first["repeat"] == 0], SIM)[0]
    assert single["delta_cv_excess"] is None and single["p_cv_excess"] is None
    assert single["n_pairs"] == 48 and single["delta_sr"] == pytest.approx(-8 / 48)


def test_sequential_p_is_valid_under_the_null_and_resolves_small_p():
    from scipy import stats as sps

    from roboview.eval.statistics.significance import sequential_p

    rng = np.random.default_rng(7)

    def p_of(observed, max_draws=100_000):
        return sequential_p(observed, rng.normal(size=1000), lambda b: rng.normal(size=b), 20, max_draws)

    # Known truth 1: the observed statistic drawn from the null itself -> P(p ≤ α) ≤ α.
    ps = np.array([p_of(x).p_value for x in rng.normal(size=3000)])
    for alpha in (0.01, 0.05, 0.2):
        assert np.mean(ps <= alpha) <= alpha + 3 * math.sqrt(alpha * (1 - alpha) / len(ps))
    assert within_binomial(float(np.mean(ps <= 0.5)), 0.5, len(ps))  # not conservative either
    # Known truth 2: a statistic whose exact p is 1e-3 is resolved (h = 20: relative error ≈ 22 %), beyond
    # the fixed 1,000-draw floor and after about h / p draws, not the maximum.
    estimates = [p_of(sps.norm.isf(1e-3)) for _ in range(20)]
    assert 5e-4 < np.median([e.p_value for e in estimates]) < 2e-3
    assert all(10_000 < e.draws < 100_000 and not e.at_floor for e in estimates)
    # Beyond what any draw reaches: the floor 1 / (max_draws + 1), flagged.
    extreme = p_of(10.0, max_draws=50_000)
    assert extreme.at_floor and extreme.draws == 50_000 and extreme.p_value == pytest.approx(1 / 50_001)


def test_one_repeat_has_no_noise_floor_for_the_cv_but_the_glm_still_tests():
    """With one episode per cell every within-block permutation leaves the CV unchanged, so cv_excess would read 0
    under any bias: it is null, and the GLM test still finds a strong bias."""
    frame, _ = simulate_split(np.random.default_rng(5), 12, 4, 1, 3.0, 0.5)
    cfg = MetricsConfig(n_perm=50, max_perm=50, n_glm=50, n_boot=20)
    single = split_metrics(frame, cfg)
    assert single["cv"] > 0.5 and single["cv_null"] is None and single["cv_excess"] is None
    assert single["p_value_cv"] is None and single["cv_excess_ci95"] is None
    assert single["p_value"] < 0.05
    # A second repeat gives the permutations something to move: the floor and the excess are measured.
    two, _ = simulate_split(np.random.default_rng(5), 12, 4, 2, 3.0, 0.5)
    double = split_metrics(two, cfg)
    assert double["cv_null"] is not None and double["cv_excess"] > 0 and double["p_value_cv"] < 0.05


def test_a_strong_bias_reports_p_below_1e_4_and_the_report_says_where_a_floor_binds():
    from roboview.eval.reporting.format import p_fmt

    frame, _ = simulate_split(np.random.default_rng(3), 9, 4, 5, 2.0, 0.7)
    m = split_metrics(frame)  # default: up to 20,000 permutations
    assert m["p_value_cv"] < 1e-4 and m["p_value_cv_draws"] == 20_000 and m["p_value_cv_at_floor"]
    assert p_fmt(m["p_value_cv"], m["p_value_cv_at_floor"]) == "≤ 5.0e-05"
    # None of the GLM calibration's 200 refits reaches the statistic: beyond their floor the p-value is the χ² tail
    # stretched over their upper quantiles, so it resolves (no "≤ 0.0050").
    assert m["p_value_method"] == "permutation+scaled_chi2_tail" and not m["p_value_at_floor"]
    assert m["p_value"] < 1e-4 and not p_fmt(m["p_value"], m["p_value_at_floor"]).startswith("≤")
    # --metrics.max_glm=N refits more permutations instead (Besag–Clifford), down to 1 / (N + 1).
    refined = split_metrics(frame, MetricsConfig(n_perm=100, max_perm=100, n_glm=50, max_glm=300))
    assert refined["p_value"] == pytest.approx(1 / 301) and refined["p_value_at_floor"]
    assert refined["lrt"]["draws"] == 300 and refined["p_value_method"] == "permutation"
    null, _ = simulate_split(np.random.default_rng(4), 9, 4, 5, 0.0, 0.7)
    quiet = split_metrics(null)
    # stops early when p is large
    assert quiet["p_value_cv_draws"] < 1000 and not quiet["p_value_cv_at_floor"]


def test_adaptive_paired_comparison_keeps_alpha_under_optional_stopping_and_stops_early():
    """Two policies on the same pairs, looked at after every round and stopped at the first crossing: equal
    policies are called different in at most α of comparisons; a 15-point SR gap is called, the right way round,
    in well under the planned rounds."""
    from roboview.eval.statistics.sequential_compare import (
        CompareDesign,
        rounds_needed,
        sign_boundaries,
        sr_looks,
    )

    def simulate(rng, delta, pairs=40, rounds=8):
        p = rng.uniform(0.3, 0.8, pairs)[:, None]
        u = rng.random((pairs, rounds))
        v = np.where(
            rng.random((pairs, rounds)) < 0.5, u, rng.random((pairs, rounds))
        )  # common random numbers
        return u < p, v < p + delta

    rng, design = np.random.default_rng(7), CompareDesign(alpha=0.05, max_repeats=8)
    null = [sr_looks(*simulate(rng, 0.0), design) for _ in range(600)]
    false = np.mean([r["verdict"] in ("A better", "B better") for r in null])
    assert within_binomial(float(false), 0.05, len(null)), false
    assert {r["verdict"] for r in null} >= {"not separated"}
    gap = [sr_looks(*simulate(rng, 0.15), design) for _ in range(200)]
    assert np.mean([r["verdict"] == "B better" for r in gap]) > 0.9
    assert not any(r["verdict"] == "A better" for r in gap)
    assert np.mean([r["look"] or 8 for r in gap]) < 4  # of 8 planned rounds
    # Each look spends its share; the spending sums to α.
    assert sum(design.spent(k) for k in range(1, 9)) == pytest.approx(0.05)
    # The SR boundaries spend it jointly and exactly: null walks over the looks cross at close to α, not below
    # it as the union bound of per-look levels would.
    discordant = [30 * k for k in range(1, 9)]
    bounds = np.array(sign_boundaries(discordant, design))
    walks = np.cumsum(rng.random((20_000, 240)) < 0.5, axis=1)[:, np.array(discordant) - 1]
    crossed = (np.abs(2 * walks - np.array(discordant)) >= bounds).any(axis=1).mean()
    assert 0.04 <= crossed <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / 20_000), crossed
    # Undecided after 2 rounds of a clear trend: the rounds still needed, from its discordant pairs.
    a, b = np.zeros((20, 2), bool), np.zeros((20, 2), bool)
    b[0:4, 0] = b[4:7, 1] = a[7, 1] = True  # B wins 7 of the 8 discordant pairs: p 0.07, not yet
    early = sr_looks(a, b, design)
    assert (
        early["verdict"] == "undecided" and early["needs"] == 2
    )  # 4 discordant a round at 7:1 cross at round 4
    # The projection uses the boundaries the looks use: two more rounds like the first two decide at exactly that look.
    later = sr_looks(np.hstack([a, a]), np.hstack([b, b]), design)
    assert later["verdict"] == "B better" and later["look"] == 2 + early["needs"]
    assert rounds_needed(a, a, design) is None  # no discordant pair: no difference to wait for


@pytest.mark.parametrize("tau", [0.0, 0.6])
def test_cv_excess_interval_covers_the_noise_free_cv(tau):
    """The bootstrap interval of cv_excess holds the true (noise-free) CV of the simulated policy at about its
    nominal 95 % (the full grid, τ ∈ {0, 0.3, 0.6} × n ∈ {2, 5, 10}, is benchmarks/cv_excess_interval.py)."""
    rng = np.random.default_rng(11 + int(10 * tau))
    cfg = MetricsConfig(n_perm=100, n_glm=1, max_perm=100, n_boot=100)
    hits, reps = 0, 30
    for _ in range(reps):
        frame, truth = simulate_split(rng, 9, 4, 5, tau, 0.7)
        m = split_metrics(frame, cfg)
        lo, hi = m["cv_excess_ci95"]
        assert lo <= m["cv_excess"] + 0.1 and hi >= 0.0  # an interval, near its estimate
        hits += lo - 1e-12 <= truth <= hi + 1e-12
    assert hits / reps >= 0.95 - 3 * math.sqrt(0.95 * 0.05 / reps), hits


def test_paired_rounds_compare_the_instances_and_rounds_both_policies_completed():
    import pandas as pd

    from roboview.eval.statistics.sequential_compare import paired_rounds

    rows = pd.DataFrame(
        {
            "policy": ["A"] * 5 + ["B"] * 6,
            "instance_id": ["i1", "i1", "i2", "i2", "i1", "i1", "i1", "i2", "i2", "i3", "i3"],
            "repeat": [0, 1, 0, 1, 2, 0, 1, 0, 1, 0, 1],
            "success": [1, 0, 1, 1, 1, 0, 0, 1, 1, 1, 0],
        }
    ).astype({"success": bool})
    a, b = paired_rounds(rows, "A", "B")  # i3 only B ran; round 2 only A started
    assert a.tolist() == [[True, False], [True, True]] and b.tolist() == [[False, False], [True, True]]
