"""What the report says when a test could not judge, and what it leaves out when the benchmark holds nothing."""

from __future__ import annotations

import math

import pytest

from roboview.eval.reporting.format import bias_status
from roboview.eval.reporting.plots import category_stats
from roboview.pipelines.report import ReportConfig, run
from tests.helpers.episodes import FAST, make_episodes, write

pytestmark = pytest.mark.fast


def test_bias_status_separates_untestable_from_unbiased():
    assert bias_status({"sr": 0.0, "p_value": None}) == ("not testable", "every episode failed")
    assert bias_status({"sr": 1.0, "p_value": 1.0}) == ("not testable", "every episode succeeded")
    assert bias_status({"sr": 0.5, "p_value": None}) == ("not testable", "too few episodes for the test")
    assert bias_status({"sr": 0.5, "p_value": 0.01}) == ("bias", "")
    assert bias_status({"sr": 0.5, "p_value": 0.3}) == ("no bias detected", "")


def test_a_policy_that_fails_everything_is_not_called_unbiased(tmp_path):
    path = write(make_episodes("random", 1).assign(success=False), tmp_path / "random.parquet")
    result = run(ReportConfig(results=str(path), output_dir=str(tmp_path / "rep"), plots=False, **FAST))
    text = (result.output_dir / "report.md").read_text()
    summary = text[text.index("## Summary") : text.index("## Table 1")]
    row = next(line for line in summary.splitlines() if line.startswith("| random"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    n = len(result.metrics["splits"])
    assert cells[4] == "none" and cells[5] == "—" and cells[6].count("(every episode failed)") == n


def test_absent_color_categories_are_left_out_not_drawn_as_zero():
    per = {
        "a": {"red": {"sr": 0.5, "n_episodes": 4}, "gray": {"sr": 0.0, "n_episodes": 2}},
        "b": {"red": {"sr": 1.0, "n_episodes": 4}},
    }
    table = category_stats(per)
    assert list(table) == ["red", "gray"]  # CATEGORIES order, only those with episodes
    assert table["red"][0] == {"sr": 0.5, "n_episodes": 4} and table["red"][1] == {"sr": 1.0, "n_episodes": 4}
    assert (
        table["gray"][0]["sr"] == 0.0
        and math.isnan(table["gray"][1]["sr"])
        and table["gray"][1]["n_episodes"] == 0
    )


def test_a_rerun_with_nothing_new_says_so_instead_of_nan(capsys):
    from pathlib import Path

    from roboview.demos.collection import CollectResult
    from roboview.pipelines.collect import summary as collect_summary
    from roboview.pipelines.evaluate import EvaluateResult, rate_text

    assert (
        rate_text(EvaluateResult(Path("o"), 171, 0, 0.877, 3.0))
        == "already complete, nothing new to run; SR 87.7%"
    )
    assert rate_text(EvaluateResult(Path("o"), 10, 10, 0.5, 36.0)) == "10 new, SR 50.0%, 1000 episodes/h"
    collect_summary(None, CollectResult(Path("ds"), 6, 0, 0, 0, 0.1))
    out = capsys.readouterr().out
    assert "nan" not in out and "already complete, nothing new to collect" in out


def test_the_values_against_the_control_arm_carry_their_paired_interval():
    """report.md and report.html name the values that differ from the control arm with Δ ×100 and its paired
    interval: blue succeeds in 2 of 12 seeds the control arm all succeeds in."""
    import pandas as pd

    from roboview.eval.reporting.format import against_control
    from roboview.eval.statistics.compare import control_deltas

    pairs = pd.DataFrame({"context_id": ["c0"] * 6 + ["c1"] * 6, "repeat": list(range(6)) * 2})
    rows = pd.concat(
        [pairs.assign(value="blue", success=[1, 1] + [0] * 10), pairs.assign(value="red", success=1)]
    )
    deltas = control_deltas(pairs.assign(success=1), rows)
    # A margin is empty (the control arm never fails), so φ = 0: Δ ∓ the root sum of squares of the Wilson distances,
    # l(2/12) = 0.0470, u(2/12) = 0.4480, l(12/12) = 12 / (12 + 1.96²) = 0.7575.
    assert deltas["blue"]["delta_control_ci95"] == pytest.approx([-0.9530, -0.4619], abs=1e-4)
    assert against_control({"per_value": deltas}) == (
        "; against the control arm (same seeds, McNemar p < 0.05; Δ ×100 [paired 95 % CI]): "
        "blue -83.33 [-95.30, -46.19] (p 0.0020)"
    )
