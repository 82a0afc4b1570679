"""The statistics validated by simulation against known truth (synthetic tables; no simulator).

A policy "with logit-SD τ bias" succeeds on value v in context c with p = logistic(α + β_v),
β_v ~ N(0, τ²). τ = 0 is no bias at all. Tolerances are binomial: with N simulated tables a
rejection rate at level 0.05 has standard error √(0.05·0.95/N).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from eval.metrics import MetricsConfig, interaction_metrics, split_metrics
from eval.stats import lrt_power, repeats_needed
from roboview_data.instances import episode_seed, generate_suite, load_preset

SIM = MetricsConfig(n_perm=100, n_glm=40)


def simulate(rng: np.random.Generator, n_values: int, n_contexts: int, repeats: int, tau: float,
             sr: float) -> tuple[pd.DataFrame, float]:
    """An episodes table with independent outcomes, and the noise-free CV of its true p(v, c)."""
    beta = rng.normal(0.0, tau, n_values)
    p = 1 / (1 + np.exp(-(math.log(sr / (1 - sr)) + beta)))[:, None].repeat(n_contexts, axis=1)
    success = rng.random((n_values, n_contexts, repeats)) < p[:, :, None]
    v, c, r = np.meshgrid(np.arange(n_values), np.arange(n_contexts), np.arange(repeats), indexing="ij")
    v, c = v.ravel(), c.ravel()
    frame = pd.DataFrame({"policy": "p", "split": "color", "factor": "color", "value": [f"v{x}" for x in v],
                          "context_id": [f"c{x}" for x in c], "instance_id": [f"{a}/{b}" for a, b in zip(v, c)],
                          "repeat": r.ravel(), "success": success.ravel()})
    return frame, float(np.mean(p.std(axis=0) / p.mean(axis=0)))


def run_many(n_sims: int, seed: int, **design) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n_sims):
        table, true_cv = simulate(rng, **design)
        m = split_metrics(table, SIM)
        qs = [s["q_value"] for s in m["per_value"].values() if s["q_value"] is not None]
        rows.append({"p": m["p_value"], "p_cv": m["p_value_cv"], "cv": m["cv"], "cv_excess": m["cv_excess"],
                     "true_cv": true_cv, "min_q": min(qs, default=1.0), "method": m["p_value_method"]})
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
    assert set(null_dense["method"]) == {"asymptotic"} and set(null_sparse["method"]) == {"permutation"}
    for sims in (null_dense, null_sparse):
        rate = float(np.mean(sims["p"] < 0.05))
        assert within_binomial(rate, 0.05, len(sims)), rate
        assert rate > 0.0  # a test that never rejects is not calibrated either


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
        logit = rng.normal(0, 0.3, 4)[:, None] + np.linspace(-1.5, 1.5, 6)[None, :] + 0.5  # A (4) + B (6)
        p = 1 / (1 + np.exp(-logit))
        success = rng.random((4, 6, 10)) < p[:, :, None]
        rows = [{"policy": "p", "split": "A_x_B", "factor": "A|B", "value": f"a{a}|b{b}", "context_id": "c*",
                 "instance_id": f"{a}/{b}", "repeat": r, "success": bool(success[a, b, r])}
                for a in range(4) for b in range(6) for r in range(10)]
        m = interaction_metrics(pd.DataFrame(rows), SIM)
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
    assert abs(float(np.mean(sims["p"] < 0.05)) - predicted) < 0.15, predicted
    # The paper's layouts at τ = 0.3: more values need fewer repeats (141 colors: 2; 21 poses: 6).
    assert [repeats_needed(v, 11, 0.3, 0.7) for v in (141, 21, 9)] == [2, 6, 10]


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
    assert len({i.context_id for i in suite}) >= 3 and len({i.seed for i in suite}) == len({i.context_id for i in suite})
