"""A model repo's `.eval_results` file from a real result bundle, published as a dry run: the `vision` policy on the
shared `tiny` benchmark's color split, one repeat (24 episodes: its control arm, red, runs in it, and the policy
misses the colors it takes for the box or the table). Every entry is checked against the bundle's own metrics.json,
read back by huggingface_hub's parser, and its task id against the benchmark's eval.yaml."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.slow

SPLIT = "color"


@pytest.fixture(scope="module")
def color_results(tmp_path_factory, tiny_benchmark) -> Path:
    """`vision` on the tiny benchmark's whole color split (8 values × 3 contexts), one repeat, 60 steps."""
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.policies.types import policy_config

    out = tmp_path_factory.mktemp("eval_results") / "vision"
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(tiny_benchmark), SPLIT),
            policy_config("vision"),
            EvalConfig(n_repeats=1, num_workers=1, image_size=64, max_steps=60),
            str(out),
        )
    )
    return out


def dry_run(results: Path, staging: Path, capsys, per_value: bool) -> tuple[list[dict], dict, str]:
    """`roboview-publish --dry_run=true` of `results`: the .eval_results entries, the bundle's metrics.json and what
    was printed."""
    import json

    from huggingface_hub import parse_eval_result_entries

    from roboview.pipelines.publish import main

    args = [
        f"--results={results}",
        "--repo_id=lab/vision-results",
        "--benchmark_repo_id=lab/roboview-bias",
        "--model_repo_id=lab/vision",
        f"--staging_dir={staging}",
        "--dry_run=true",
    ]
    main(args + (["--results_per_value=true"] if per_value else []))
    printed = capsys.readouterr().out
    path = staging.with_name(staging.name + "_eval_results") / ".eval_results" / "roboview-bias.yaml"
    entries = yaml.safe_load(path.read_text())
    assert f"{len(entries)} entries, written to {path}" in printed
    assert len(parse_eval_result_entries(entries)) == len(entries)  # the Hub's own reader takes every entry
    for e in entries:  # the Hub's layout: nothing beyond its fields
        assert set(e) <= {"dataset", "value", "verifyToken", "date", "source", "notes"}
        assert (
            set(e["dataset"]) == {"id", "task_id", "revision"} and e["dataset"]["id"] == "lab/roboview-bias"
        )
        assert e["source"]["url"] == "https://huggingface.co/datasets/lab/vision-results"
    return entries, json.loads((staging / "report" / "metrics.json").read_text()), printed


def pct(x: float) -> str:
    return f"{100 * x:.2f}"


def interval(ci: list[float]) -> str:
    return f"[{pct(ci[0])}, {pct(ci[1])}]"


def declared(tiny_benchmark: Path) -> list[str]:
    return [t["id"] for t in yaml.safe_load((tiny_benchmark / "eval.yaml").read_text())["tasks"]]


def test_one_entry_per_factor_and_its_control_arm(color_results, tiny_benchmark, tmp_path, capsys):
    entries, metrics, _ = dry_run(color_results, tmp_path / "bundle", capsys, per_value=False)
    m = metrics["splits"][SPLIT]
    by_id = {e["dataset"]["task_id"]: e for e in entries}
    assert list(by_id) == [SPLIT, f"{SPLIT}/control"]
    factor, control = by_id[SPLIT], by_id[f"{SPLIT}/control"]
    assert factor["value"] == round(100 * m["sr"], 2) and control["value"] == round(100 * m["sr_control"], 2)
    # The policy misses some colors; the control arm (red, the color baseline) it does not: two different numbers.
    assert factor["value"] < control["value"] == 100.0
    assert f"n={m['n_episodes']} episodes, 95 % Clopper–Pearson {interval(m['sr_ci95'])}" in factor["notes"]
    assert f"control arm {pct(m['sr_control'])} {interval(m['sr_control_ci95'])}" in factor["notes"]
    assert (
        f"n={m['n_control_episodes']} episodes, 95 % Clopper–Pearson {interval(m['sr_control_ci95'])}"
        in control["notes"]
    )
    assert m["n_control_episodes"] == 3  # red in each of the 3 contexts
    assert set(by_id) <= set(declared(tiny_benchmark))


def test_one_entry_per_value_with_its_difference_to_the_control_arm(
    color_results, tiny_benchmark, tmp_path, capsys
):
    entries, metrics, _ = dry_run(color_results, tmp_path / "bundle", capsys, per_value=True)
    m = metrics["splits"][SPLIT]
    values = m["per_value"]
    assert len(values) == 8
    assert len(entries) == 1 + 1 + len(values)  # the factor, its control arm, each value
    by_id = {e["dataset"]["task_id"]: e for e in entries}
    assert list(by_id)[:2] == [SPLIT, f"{SPLIT}/control"]
    assert set(by_id) <= set(declared(tiny_benchmark))
    for value, s in values.items():
        e = by_id[f"{SPLIT}={value}"]
        assert e["value"] == round(100 * s["sr"], 2)
        assert f"n={s['n_episodes']} episodes, 95 % Clopper–Pearson {interval(s['sr_ci95'])}" in e["notes"]
        delta = f"Δ vs control {100 * s['delta_control']:+.2f} {interval(s['delta_control_ci95'])}"
        assert delta in e["notes"] and f"over {s['n_control_pairs']} pairs" in e["notes"]
        assert f"McNemar p={s['p_control']:.4f}" in e["notes"]
    # The numbers are each value's own: the control arm's value scores as the control arm, a missed color below.
    assert by_id[f"{SPLIT}=red"]["value"] == by_id[f"{SPLIT}/control"]["value"] == 100.0
    assert min(e["value"] for e in entries) < 100.0
    assert any(s["delta_control"] < 0 for s in values.values())
