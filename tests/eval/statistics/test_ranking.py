"""Rankings of many policies: the known order is recovered, and no difference the tests do not support is claimed."""

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.metrics import MetricsConfig, compute_all_metrics
from roboview.eval.statistics.ranking import compact_letters, holm, rank_table

pytestmark = pytest.mark.fast

FAST = MetricsConfig(n_perm=100, n_glm=20, max_perm=100)


def policies(rates: dict[str, float], repeats: int, seed: int = 0) -> pd.DataFrame:
    """Policies of known SR on one color split (6 values × 4 contexts), the same instances and repeats."""
    rng = np.random.default_rng(seed)
    rows = []
    for name, rate in rates.items():
        for v in range(6):
            for c in range(4):
                for r in range(repeats):
                    rows.append(
                        {
                            "policy": name,
                            "split": "color",
                            "factor": "color",
                            "value": f"v{v}",
                            "context_id": f"c{c}",
                            "instance_id": f"{v}/{c}",
                            "repeat": r,
                            "success": bool(rng.random() < rate),
                        }
                    )
    return pd.DataFrame(rows)


def test_compact_letters_follow_the_differences():
    order = ["a", "b", "c", "d"]
    assert compact_letters(order, set()) == {"a": "a", "b": "a", "c": "a", "d": "a"}
    # a ≠ c, a ≠ d, b ≠ d: {a, b}, {b, c}, {c, d} overlap in a chain
    diff = {frozenset(p) for p in (("a", "c"), ("a", "d"), ("b", "d"))}
    assert compact_letters(order, diff) == {"a": "a", "b": "ab", "c": "bc", "d": "c"}


def test_rank_ranges_claim_only_what_holm_supports():
    values = {"x": 0.9, "y": 0.8, "z": 0.2}
    p = {frozenset(("x", "y")): 0.03, frozenset(("x", "z")): 0.001, frozenset(("y", "z")): 0.02}
    # Holm over 3: 0.001·3 = 0.003 < .05; 0.02·2 = 0.04 < .05; 0.03·1 = 0.03 < .05 -> all differ
    assert [r["rank_range"] for r in rank_table(values, p, True)] == [[1, 1], [2, 2], [3, 3]]
    # Holm by hand: sorted p × (m, m − 1, …), then non-decreasing (0.025·2 → 0.06), capped at 1
    assert holm([0.025, 0.001, 0.02, 0.5]).tolist() == pytest.approx([0.06, 0.004, 0.06, 0.5])
    assert holm([0.6, 0.7]).tolist() == [1.0, 1.0] and holm([]).size == 0
    p[frozenset(("x", "y"))] = 0.2  # x and y no longer separable: they share ranks 1–2 and a letter
    ranked = rank_table(values, p, True)
    assert [(r["policy"], r["group"], r["rank_range"]) for r in ranked] == [
        ("x", "a", [1, 2]),
        ("y", "a", [1, 2]),
        ("z", "b", [3, 3]),
    ]


def test_a_known_order_is_recovered_and_small_samples_claim_no_order():
    big = compute_all_metrics(policies({"p1": 0.95, "p2": 0.93, "p3": 0.55, "p4": 0.1}, repeats=8), FAST)
    by_sr = big["rankings"]["splits"]["color"]["sr"]
    assert [r["policy"] for r in by_sr][2:] == ["p3", "p4"] and {r["policy"] for r in by_sr[:2]} == {
        "p1",
        "p2",
    }
    assert [r["rank_range"] for r in by_sr] == [[1, 2], [1, 2], [3, 3], [4, 4]]
    assert by_sr[0]["group"] == by_sr[1]["group"] != by_sr[2]["group"] != by_sr[3]["group"]
    overall = big["rankings"]["overall"]["sr"]
    assert [r["rank_range"] for r in overall][2:] == [[3, 3], [4, 4]]
    # 24 episodes each at 0.55 / 0.5 / 0.45: this draw even observes the order reversed (q3 first), and the
    # ranking claims no order at all.
    small = compute_all_metrics(policies({"q1": 0.55, "q2": 0.5, "q3": 0.45}, repeats=1, seed=0), FAST)
    ranked = small["rankings"]["splits"]["color"]["sr"]
    assert ranked[0]["policy"] == "q3"
    assert all(r["rank_range"] == [1, 3] and r["group"] == "a" for r in ranked)


def test_equal_policies_are_split_no_more_often_than_alpha():
    from roboview.eval.statistics.significance import paired_success_test

    rng = np.random.default_rng(5)
    claimed = 0
    sims = 200
    for _ in range(sims):  # three interchangeable policies, 60 paired episodes, SR 0.6
        outcome = {name: rng.random(60) < 0.6 for name in "abc"}
        p = {
            frozenset((x, y)): paired_success_test(outcome[x], outcome[y])
            for i, x in enumerate("abc")
            for y in "abc"[i + 1 :]
        }
        ranked = rank_table({n: float(o.mean()) for n, o in outcome.items()}, p, True)
        claimed += any(r["rank_range"] != [1, 3] for r in ranked)
    assert claimed / sims <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / sims)  # Holm: family-wise error ≤ α


def test_two_policies_get_no_ranking():
    assert "rankings" not in compute_all_metrics(policies({"a": 0.9, "b": 0.1}, repeats=2), FAST)


def test_the_report_prints_the_rankings():
    from roboview.eval.reporting.markdown import render_markdown

    metrics = compute_all_metrics(policies({"p1": 0.95, "p2": 0.93, "p3": 0.55, "p4": 0.1}, repeats=8), FAST)
    text = render_markdown(metrics, {})
    line = next(x for x in text.splitlines() if x.startswith("| color | SR |"))
    assert "p3" in line and "(b; 3)" in line and "(a; 1–2)" in line
    assert (
        pytest.approx(metrics["rankings"]["splits"]["color"]["sr"][3]["value"])
        == metrics["policies"]["p4"]["splits"]["color"]["sr"]
    )


def test_holm_equals_statsmodels_multipletests():
    # The adjustment ranking uses is statsmodels' Holm, without its garbage collection on every call.
    from statsmodels.stats.multitest import multipletests

    rng = np.random.default_rng(0)
    for m in (1, 2, 3, 7, 20):
        p = np.append(rng.uniform(0, 0.1, m - 1), 0.02)  # ties included where 0.02 repeats
        assert holm(list(p)).tolist() == pytest.approx(multipletests(p, method="holm")[1].tolist(), abs=1e-12)
