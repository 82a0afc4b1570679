"""roboview.pipelines.audit: another benchmark's per-episode table, mapped onto RoboView's statistics, on known truth."""

import json

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics.metrics import MetricsConfig, compute_metrics
from roboview.eval.statistics.simulate import simulate_split
from roboview.pipelines.audit import main

pytestmark = pytest.mark.fast

FAST = ["--metrics.n_perm=300", "--metrics.n_glm=40", "--metrics.max_perm=300"]


@pytest.fixture(scope="module")
def truth():
    """camera: a strong bias (logit SD 1.5); light: none. One table, one factor column, shuffled rows."""
    rng = np.random.default_rng(11)
    camera, _ = simulate_split(rng, 6, 4, 5, 1.5, 0.7)
    light, _ = simulate_split(rng, 5, 4, 5, 0.0, 0.7)
    frames = []
    for name, frame in (("camera", camera), ("light", light)):
        frames.append(
            pd.DataFrame(
                {
                    "category": name,
                    "variant": frame["value"],
                    "base_task": frame["context_id"],
                    "trial": frame["repeat"],
                    "outcome": np.where(frame["success"], "success", "failure"),
                    "model": "pi0",
                }
            )
        )
    return camera, light, pd.concat(frames).sample(frac=1, random_state=0).reset_index(drop=True)


def audit(tmp_path, table, *extra):
    path = tmp_path / "rollouts.csv"
    table.to_csv(path, index=False)
    main(
        [
            f"--results={path}",
            "--map.factor=category",
            "--map.value=variant",
            "--map.context=base_task",
            "--map.success=outcome",
            f"--output_dir={tmp_path / 'out'}",
            *FAST,
            *extra,
        ]
    )
    return json.loads((tmp_path / "out" / "metrics.json").read_text()), (
        tmp_path / "out" / "report.md"
    ).read_text()


def test_the_audit_finds_the_known_bias_and_equals_roboview_on_the_same_episodes(tmp_path, truth):
    camera, light, table = truth
    metrics, report = audit(tmp_path, table, "--map.repeat=trial")
    splits = metrics["splits"]
    # none of 40 draws reached it: p from the χ² tail stretched over them, below their floor 1/41
    assert (
        splits["camera"]["p_value"] < 1 / 41
        and splits["camera"]["p_value_method"] == "permutation+scaled_chi2_tail"
    )
    assert splits["light"]["p_value"] > 0.05
    # The same numbers RoboView computes on the simulated episodes themselves (the mapping loses nothing;
    # Monte Carlo p-values differ only by their draws, which follow row order).
    cfg = MetricsConfig(n_perm=300, n_glm=40, max_perm=300)
    for name, frame in (("camera", camera), ("light", light)):
        direct = compute_metrics(frame.assign(split=name, factor=name), cfg)["splits"][name]
        for key in ("sr", "cv", "n_episodes", "n_contexts", "n_instances"):
            assert splits[name][key] == pytest.approx(direct[key]), (name, key)
        assert splits[name]["lrt"]["statistic"] == pytest.approx(direct["lrt"]["statistic"], rel=1e-6)
        assert {v: m["sr"] for v, m in splits[name]["per_value"].items()} == pytest.approx(
            {v: m["sr"] for v, m in direct["per_value"].items()}
        )
    assert splits["camera"]["power"]["repeats"] == 5 and 0 < splits["camera"]["power"]["power"] < 1
    assert "## Audit: mapping and power" in report and "success ← outcome" in report


def test_file_order_numbers_repeats_and_a_policy_column_gives_paired_comparisons(tmp_path, truth):
    _, _, table = truth
    two = pd.concat([table, table.assign(model="pi05", outcome="success")])
    metrics, report = audit(tmp_path, two.drop(columns=["trial"]), "--map.policy=model")
    assert set(metrics["policies"]) == {"pi0", "pi05"}
    assert {c["split"] for c in metrics["comparisons"]} == {"camera", "light"}
    assert metrics["policies"]["pi05"]["splits"]["camera"]["sr"] == 1.0


def test_bad_mappings_fail_naming_the_column_and_what_is_allowed(tmp_path, truth, capsys):
    _, _, table = truth
    for extra, message in (
        (["--map.repeat=attempt"], "has no column(s) ['attempt']; its columns: category"),
        (["--map.success=variant"], "are not outcomes; allowed: 1/0, true/false"),
    ):
        with pytest.raises(SystemExit):
            audit(tmp_path, table, *extra)
        assert message in capsys.readouterr().err
    dup = pd.concat([table, table.head(1)])
    with pytest.raises(SystemExit):
        audit(tmp_path, dup, "--map.repeat=trial")
    assert "episodes repeat a (policy, factor, value, context, repeat)" in capsys.readouterr().err
