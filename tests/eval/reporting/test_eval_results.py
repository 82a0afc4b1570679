"""The `.eval_results` entries of a factor a task takes apart (LIBERO-plus's camera: its total, each single change,
the no-change view) from the decomposition the statistics compute on a synthetic table; the benchmark's eval.yaml
declaring their task ids; and `--results_per_value` refused, naming the flag, before any work."""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from roboview.benchmark.card import write_eval_yaml
from roboview.benchmark.eval_tasks import analysis_task_ids
from roboview.eval.reporting.eval_results import eval_result_entries, eval_results_yaml, metric_scores
from roboview.eval.statistics import decompose
from roboview.tasks import load_task
from tests.eval.statistics.test_decompose import synthetic

pytestmark = pytest.mark.fast


@pytest.fixture(scope="module")
def camera():
    """LIBERO-plus's camera design and its decomposition of a synthetic table (6 blocks)."""
    design = next(d for d in load_task("liberoplus").analyses if d.key == "liberoplus_camera")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(decompose, "N_BOOT", 200)
        return design, decompose.compute(synthetic(design), design)


def test_a_decomposed_factor_scores_its_total_each_single_change_and_the_no_change_view(camera):
    design, result = camera
    entries = eval_result_entries(
        {"splits": {}, "analyses": {design.key: result}},
        benchmark_repo_id="lab/liberoplus-bench",
        results_repo_id="lab/results",
        date="2026-01-15T10:30:00+00:00",
        revision="v1",
    )
    data = yaml.safe_load(eval_results_yaml(entries))
    by_id = {e["dataset"]["task_id"]: e for e in data}
    # The ids the benchmark's eval.yaml declares for the analysis, in its order.
    assert list(by_id) == [i for i, _ in analysis_task_ids(design)]
    assert list(by_id) == [
        "liberoplus_camera",
        *(f"liberoplus_camera/{f.column}" for f in design.sub_factors),
        "liberoplus_camera/no_change",
    ]
    total, base = result[design.name][design.micro[0]], result[design.name]["no_change"]
    assert by_id["liberoplus_camera"]["value"] == round(100 * total["sr"], 2)
    assert (
        f"n={total['n']} episodes, 95 % Clopper–Pearson [{100 * total['ci95'][0]:.2f}, "
        in (by_id["liberoplus_camera"]["notes"])
    )
    assert by_id["liberoplus_camera/no_change"]["value"] == round(100 * base["sr"], 2)
    for kind in result["kinds"].values():
        if len(kind["factors"]) != 1:
            continue
        e = by_id[f"liberoplus_camera/{kind['factors'][0]}"]
        assert e["value"] == round(100 * kind["sr"], 2)
        lo, hi = kind["ci95_effect"]
        assert f"{100 * kind['effect']:+.2f} [{100 * lo:.2f}, {100 * hi:.2f}] points" in e["notes"]
        assert f"over {kind['n_blocks']} blocks" in e["notes"] and f"p={kind['p']:.4f}" in e["notes"]
    # The synthetic costs differ by kind: the entries are each kind's own number, not one repeated.
    assert len({e["value"] for e in data}) > 2


def test_the_benchmark_declares_every_task_id_its_entries_name(camera, tmp_path):
    """eval.yaml of a LIBERO-plus split: the split, its control arm, each value its table holds, and the analysis's
    ids; every entry the scores name, per value too, is among them."""
    design, result = camera
    split = "liberoplus_view_azimuth"
    (tmp_path / "data").mkdir()
    values = ["0", "30", "330"]
    pq.write_table(
        pa.table({"factor": ["view_azimuth"] * 3, "value": values}), tmp_path / "data" / f"{split}.parquet"
    )
    manifest = {"splits": {split: {"accepted": 3}}, "suite": {"preset": "p"}, "benchmark_version": "p-1"}
    write_eval_yaml(tmp_path, manifest)
    tasks = yaml.safe_load((tmp_path / "eval.yaml").read_text())["tasks"]
    ids = [t["id"] for t in tasks]
    assert ids == [
        split,
        f"{split}/control",
        *(f"{split}={v}" for v in values),
        *(i for i, _ in analysis_task_ids(design)),
    ]
    assert len(set(ids)) == len(ids)
    assert {t["splits"][0] for t in tasks if t["id"].startswith(design.key)} == {split}
    per_value = {"sr": 0.5, "sr_ci95": [0.1, 0.9], "n_episodes": 2}
    metrics = {
        "splits": {
            split: {
                "factor": "view_azimuth",
                "sr": 0.5,
                "sr_ci95": [0.2, 0.8],
                "n_episodes": 6,
                "sr_control": None,
                "n_control_episodes": 0,
                "cv_excess": None,
                "per_value": {v: per_value for v in values},
            }
        },
        "analyses": {design.key: result},
    }
    scored = [s.task_id for s in metric_scores(metrics, per_value=True)]
    assert f"{split}=330" in scored and f"{split}/control" not in scored  # no control arm ran: no entry
    assert set(scored) <= set(ids)


def error_of(args: list[str], capsys) -> str:
    from roboview.pipelines.publish import main

    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(
    "extra",
    [
        [],  # no model repo
        ["--benchmark_repo_id=lab/bench"],
    ],
)
def test_results_per_value_without_a_model_repo_is_refused_before_any_work(extra, tmp_path, capsys):
    results = tmp_path / "results"
    results.mkdir()  # no results in it: the flag's own check comes first
    err = error_of([f"--results={results}", "--repo_id=lab/r", "--results_per_value=true", *extra], capsys)
    assert "--results_per_value=true needs --results=DIR and --model_repo_id=ORG/MODEL" in err
    assert not (tmp_path / "results_bundle").exists()


def test_results_per_value_with_a_benchmark_or_a_bad_value_is_refused(tmp_path, capsys):
    err = error_of(["--repo_id=lab/r", f"--path={tmp_path}", "--results_per_value=true"], capsys)
    assert "--results_per_value=true needs --results=DIR" in err
    err = error_of(["--repo_id=lab/r", "--results=x", "--results_per_value=maybe"], capsys)
    assert "results_per_value" in err and "'maybe'" in err
