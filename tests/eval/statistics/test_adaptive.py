"""Adaptive evaluation: the group-sequential test keeps α over every look, saves episodes against the fixed
design of equal power (simulation with known truth), and runs end to end with resume."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.adaptive import Design, boundaries, decide, fixed_power, simulate
from roboview.eval.statistics.tables import MetricsConfig
from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
from roboview.policies.types import policy_config

pytestmark = pytest.mark.fast


def within(rate: float, level: float, n: int) -> bool:
    return rate <= level + 3 * math.sqrt(level * (1 - level) / n)


def test_type_one_error_stays_at_alpha_when_looking_after_every_round():
    # 9 values × 4 contexts: sparse cells, where a χ²-calibrated look would reject 12 % of null splits.
    design = Design(alpha=0.05, tau=0.6, max_repeats=6)
    result = simulate(9, 4, 0.7, 0.0, design, 600, seed=2)
    assert within(result["rejection_rate"], 0.05, 600), result
    assert result["rejection_rate"] > 0.02  # calibrated: α is spent, not wasted as by a union bound
    assert result["stopped_no_bias"] > 0.5  # under no bias most splits stop early for futility
    # Contexts at very different rates: the boundaries, calibrated at the contexts' spread, still hold α (at the
    # pooled rate alone these splits rejected 6.8 % of 3,000).
    mixed = simulate(9, 4, (0.3, 0.5, 0.7, 0.9), 0.0, design, 600, seed=3)
    assert within(mixed["rejection_rate"], 0.05, 600), mixed


def test_fewer_episodes_than_the_fixed_design_of_equal_power():
    # The paper's camera_pose shape (21 values × 11 contexts), a bias of logit SD 0.6, SR 0.7.
    adaptive = simulate(21, 11, 0.7, 0.6, Design(alpha=0.05, tau=0.6, power=0.8, max_repeats=4), 200, seed=4)
    assert adaptive["rejection_rate"] >= 0.85
    # The fixed design of that power: the same statistic, its critical value from simulated null splits.
    power = [fixed_power(21, 11, 0.7, 0.6, n, 0.05, paths=1000) for n in (1, 2, 3)]
    assert power[0] < adaptive["rejection_rate"] <= power[2], power
    fixed = np.interp(adaptive["rejection_rate"], power, [1, 2, 3])
    assert adaptive["mean_rounds"] <= 0.8 * fixed, (adaptive, fixed)


def test_boundaries_are_calibrated_and_decide_from_the_lrt(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    boundaries.cache_clear()
    design = Design(alpha=0.05, tau=0.6, max_repeats=4)
    value = np.repeat(np.arange(6), 3)
    context = np.tile(np.arange(3), 6)
    strong = np.where(value < 3, 2, 0)  # half the values never succeed, half always: a bias by any test
    decision = decide(strong, np.full(18, 2), value, context, 2, design)
    assert decision.stopped == "bias" and decision.statistic > decision.efficacy
    flat = np.ones(18, int)  # every cell 1 of 2: no sign of a bias at SR 0.5
    assert decide(flat, np.full(18, 2), value, context, 2, design).stopped == "no_bias"
    assert decide(flat, np.full(18, 1), value, context, 0, design).stopped is None  # before the first look
    # The boundaries went to the cache folder; a fresh process reads them back instead of simulating.
    stored = list((tmp_path / "roboview" / "adaptive").glob("*.json"))
    assert len(stored) == 1
    efficacy = np.array(json.loads(stored[0].read_text())["efficacy"])
    np.testing.assert_array_equal(efficacy, boundaries(6, 3, 0.0, 0.0, design)[0])
    boundaries.cache_clear()
    stored[0].write_text(json.dumps({"efficacy": [1.0] * 4, "futility": [0.0] * 4}))
    assert decide(flat, np.full(18, 2), value, context, 2, design).efficacy == 1.0
    boundaries.cache_clear()
    with pytest.raises(ValueError, match="alpha"):
        Design(alpha=1.5)


@pytest.mark.slow
def test_an_adaptive_run_stops_splits_resumes_and_is_reported(tiny_benchmark, tmp_path):
    from roboview.pipelines.report import ReportConfig
    from roboview.pipelines.report import run as report

    cfg = EvaluateConfig(
        BenchmarkConfig(str(tiny_benchmark), "color,color_x_camera_pose"),
        policy_config("expert"),
        EvalConfig(
            adaptive=True, max_repeats=3, n_repeats=2, num_workers=2, image_size=64, max_steps=60, contexts=1
        ),
        str(tmp_path / "ev"),
    )
    first = run(cfg)
    record = json.loads((tmp_path / "ev" / "adaptive.json").read_text())
    color = record["splits"]["color"]
    # The expert succeeds everywhere, so no look can tell a small bias from none: the split runs every round.
    assert color["stopped"] == "max_repeats" and color["rounds"] == 3 and color["lrt"] == 0.0
    rows = pd.read_parquet(tmp_path / "ev" / "episodes.parquet")
    assert rows.groupby("split")["repeat"].max().to_dict() == {"color": 2, "color_x_camera_pose": 1}
    assert (
        first.new_episodes == len(rows) == color["episodes"] + (rows["split"] == "color_x_camera_pose").sum()
    )
    assert run(cfg).new_episodes == 0  # a rerun recomputes the same decisions: nothing more to run
    result = report(
        ReportConfig(
            results=str(tmp_path / "ev" / "episodes.parquet"),
            output_dir=str(tmp_path / "rep"),
            metrics=MetricsConfig(n_perm=50, n_glm=10),
            plots=False,
        )
    )
    assert result.metrics["splits"]["color"]["adaptive"]["stopped"] == "max_repeats"
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "## Adaptive sampling" in text and "The sampling was adaptive" in text
