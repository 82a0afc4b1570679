"""Success by task context factor (eval/statistics/context.py), validated by simulation against known truth."""

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.context import context_breakdown, context_factor_metrics
from roboview.eval.statistics.metrics import MetricsConfig
from roboview.variation.factors import FACTORS, baselines

pytestmark = pytest.mark.fast

INSTRUCTIONS = FACTORS["instruction"].values
COLORS = ("red", "gray", "gold", "navy", "teal", "pink", "tan")


def episodes(p_by_instruction, repeats: int, rng: np.random.Generator, shapes=("cube",)) -> pd.DataFrame:
    """The color split's instruction subspace (and optionally a shape subspace): success ~ Bernoulli(p[instr])."""
    base = baselines()
    rows = []
    contexts = [("instruction", i) for i in INSTRUCTIONS] + [
        ("shape", s) for s in shapes if s != base["shape"]
    ]
    for factor, value in contexts:
        ctx = base | {factor: value}
        p = p_by_instruction[INSTRUCTIONS.index(ctx["instruction"])]
        for color in COLORS:
            for r in range(repeats):
                rows.append(
                    {
                        "policy": "sim",
                        "task": "pick_place",
                        "split": "color",
                        "factor": "color",
                        "value": color,
                        "context_id": f"{factor}={value}",
                        "instance_id": f"{value}/{color}",
                        "repeat": r,
                        "success": bool(rng.random() < p),
                        "instruction": ctx["instruction"],
                        "shape": ctx["shape"],
                        "initial_position": ctx["initial_position"],
                    }
                )
    return pd.DataFrame(rows)


def test_no_instruction_effect_rejects_at_the_nominal_rate():
    rng = np.random.default_rng(7)
    cfg = MetricsConfig(n_glm=20)
    p_values = [
        context_factor_metrics(episodes((0.5, 0.5, 0.5), 30, rng), "pick_place", "instruction", cfg)[
            "p_value"
        ]
        for _ in range(200)
    ]
    rate = np.mean(np.array(p_values) < 0.05)
    assert 0.01 <= rate <= 0.09, rate  # 200 draws at α = 0.05: a 99 % binomial band is [0.015, 0.09]


def test_a_real_instruction_effect_is_found_and_reported_per_value():
    m = context_factor_metrics(
        episodes((0.7, 0.7, 0.3), 30, np.random.default_rng(1)), "pick_place", "instruction"
    )
    assert m["p_value"] < 1e-6 and m["p_value_method"] == "asymptotic" and m["n_conditions"] == len(COLORS)
    assert list(m["per_value"]) == list(INSTRUCTIONS)
    sr = [v["sr"] for v in m["per_value"].values()]
    assert sr[2] < 0.4 < 0.6 < min(sr[:2]) and all(v["n_episodes"] == 210 for v in m["per_value"].values())
    lo, hi = m["per_value"][INSTRUCTIONS[2]]["sr_ci95"]
    assert lo < sr[2] < hi


def test_each_factor_reads_only_its_own_subspace():
    # The shape context (instruction at baseline) must not enter the instruction's table, nor vice versa.
    rows = episodes((0.9, 0.1, 0.1), 4, np.random.default_rng(2), shapes=("cube", "cylinder"))
    found = context_breakdown(rows)
    assert set(found) == {"instruction", "shape"}
    assert found["instruction"]["n_episodes"] == 3 * len(COLORS) * 4
    assert set(found["shape"]["per_value"]) == {"cube", "cylinder"}  # cube: the baseline context
    assert found["shape"]["n_episodes"] == 2 * len(COLORS) * 4
