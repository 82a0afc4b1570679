"""roboview.pipelines.audit --format: vla-eval's recording and export, and Inspect Robots' eval logs, each written by the
harness's own code with a planted bias, audited back to the planted counts."""

import json
import re
import uuid
from pathlib import Path

import pytest
from inspect_robots.eval import eval as inspect_eval
from inspect_robots.mock import CubePickEmbodiment, ScriptedPolicy
from inspect_robots.scene import Scene
from inspect_robots.scorer import operator_scorer
from inspect_robots.task import Task
from vla_eval.config import EvalConfig
from vla_eval.recording import (
    DEFAULT_FILENAME_STEM,
    EpisodeRecorder,
    RecordingStore,
    db_path_for_eval,
    recording_filename_context,
    serializable_task_kwargs,
)
from vla_eval.results.collector import ResultCollector
from vla_eval.results.export import export_db

from roboview.pipelines.audit import main
from tests.helpers import cli

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
FAST = ["--metrics.n_perm=200", "--metrics.n_glm=30", "--metrics.max_perm=200"]
INSTRUCTIONS = [f"pick up the black bowl {where} and place it on the plate" for where in ("on the stove", "next to the ramekin", "on the cookie box")]  # fmt: skip
EPISODES = 5
# LIBERO-plus category → successes of EPISODES per (base task, difficulty level): camera level 3 fails far more.
PLANTED = {
    "Camera Viewpoints": {1: 4, 2: 4, 3: 1},
    "Light Conditions": {1: 3, 2: 3, 3: 3},
    "Language Instructions": {1: 2, 2: 2},
}


def record(store, eval_id, config, tasks, outcomes, out, collector=None):
    """One benchmark entry of a vla-eval run config, recorded as vla-eval's orchestrator records it: the entry's
    metadata, then per episode an EpisodeRecorder over the task's fields, closed with its status and metrics."""
    name = EvalConfig.from_dict(config).resolved_name()
    safe_name = re.sub(r"[^\w\-.]", "_", name)
    bench_eval_id = f"{eval_id}-{safe_name}"
    metadata = {"benchmark": name, "mode": "sync", "config": config, "metric_keys": {"success": "mean"}}
    store.upsert_eval_metadata(bench_eval_id, safe_name, metadata)
    for task_idx, (task, oks) in enumerate(zip(tasks, outcomes)):
        for episode, ok in enumerate(oks):
            recorder = EpisodeRecorder(
                store=store,
                sid="shard0",
                eid=str(uuid.uuid4()),
                eval_id=bench_eval_id,
                output_dir=out / "episodes",
                filename_stem=DEFAULT_FILENAME_STEM,
                context={**serializable_task_kwargs({**task, "episode_idx": episode}), "task_idx": task_idx},
                filename_context=recording_filename_context(
                    benchmark_safe_name=safe_name, task_idx=task_idx, episode_id=episode
                ),
            )
            recorder.record_step(reward=float(ok), done=True, success=ok)
            result = {"episode_id": episode, "metrics": {"success": ok}, "steps": 1}
            # The last episode of each camera level-3 task errored (a planted failure): vla-eval counts it as failed.
            if (task.get("category"), task.get("difficulty_level"), episode) == (
                "Camera Viewpoints",
                3,
                EPISODES - 1,
            ):
                result["failure_reason"] = "server_error"
            recorder.close(
                status="error" if "failure_reason" in result else "success" if ok else "fail",
                metrics=result["metrics"],
                task_name=task["name"],
                episode_id=episode,
                steps=1,
                failure_reason=result.get("failure_reason"),
            )
            if collector is not None:
                collector.record(task["name"], result)


@pytest.fixture(scope="module")
def vla_eval_run(tmp_path_factory):
    """A LIBERO-plus run and a LIBERO-Pro run, recorded to SQLite and exported; a plain LIBERO collector JSON."""
    out = tmp_path_factory.mktemp("vla_eval")
    tasks, outcomes = [], []
    for category, levels in PLANTED.items():
        for level, k in levels.items():
            for instruction in INSTRUCTIONS:
                # LIBERO-plus' tasks as LIBEROPlusBenchmark.get_tasks lists them (task_obj is no JSON: not recorded)
                name = (
                    f"{instruction}, paraphrase {level}" if category.startswith("Language") else instruction
                )
                task = {"name": name, "suite": "libero_spatial", "task_id": len(tasks), "category": category}
                tasks.append({**task, "difficulty_level": level})
                outcomes.append([e < k for e in range(EPISODES)])
    config = {
        "benchmark": "vla_eval.benchmarks.libero_plus.benchmark:LIBEROPlusBenchmark",
        "params": {"suite": "libero_spatial", "seed": 7},
    }
    store = RecordingStore(db_path_for_eval(out, "plus"))
    store.set_run_metadata("plus", {})
    collector = ResultCollector("LIBERO", metric_keys={"success": "mean"})
    record(store, "plus", config, tasks, outcomes, out, collector)
    store.close()
    export_db(db_path_for_eval(out, "plus"), out)
    (out / "collector.json").write_text(collector.to_json())

    pro = tmp_path_factory.mktemp("vla_eval_pro")
    store = RecordingStore(db_path_for_eval(pro, "pro"))
    store.set_run_metadata("pro", {})
    for perturbation, k in ((None, 4), ("swap", 0), ("env", 4)):
        config = {
            "benchmark": "vla_eval.benchmarks.libero_pro.benchmark:LIBEROProBenchmark",
            "subname": perturbation or "base",
            "params": {"suite": "libero_goal", "perturbation": perturbation},
        }
        suite = f"libero_goal_{perturbation}" if perturbation else "libero_goal"
        pro_tasks = [{"name": f"task {i}", "suite": suite, "task_id": i} for i in range(3)]
        record(store, "pro", config, pro_tasks, [[e < k for e in range(4)]] * 3, pro)
    store.close()
    return out, pro


def audit(results, out, *extra):
    main([f"--results={results}", f"--output_dir={out}", *FAST, *extra])
    return json.loads((Path(out) / "metrics.json").read_text())


def successes(split: dict) -> dict[str, int]:
    return {v: round(m["sr"] * m["n_episodes"]) for v, m in split["per_value"].items()}


def test_vla_eval_run_folder_from_the_command_line(vla_eval_run, tmp_path):
    out, _ = vla_eval_run
    done = cli.run(
        "roboview.pipelines.audit", "--format=vla_eval", f"--results={out}", f"--output_dir={tmp_path}", *FAST
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    splits = metrics["splits"]
    assert set(splits) == set(PLANTED)
    assert sum(s["n_episodes"] for s in splits.values()) == EPISODES * len(INSTRUCTIONS) * 8 == 120
    for category, levels in PLANTED.items():
        # the errored episode (camera level 3) counts as a failure, as vla-eval counts it
        assert successes(splits[category]) == {str(v): k * len(INSTRUCTIONS) for v, k in levels.items()}
    # none of the 30 null draws reached the planted drop: p from the χ² tail stretched over them, below 1/31
    camera = splits["Camera Viewpoints"]
    assert camera["p_value"] < 1 / 31 and camera["p_value_method"] == "permutation+scaled_chi2_tail"
    assert not camera["p_value_at_floor"] and camera["n_contexts"] == 3
    assert splits["Light Conditions"]["p_value"] > 0.5
    # language variants rewrite the instruction: their base task is the suite
    assert splits["Language Instructions"]["n_contexts"] == 1
    report = (tmp_path / "report.md").read_text()
    assert (
        "(vla-eval LIBERO-plus results in recording-plus.sqlite)" in report and "factor ← category" in report
    )


def test_vla_eval_aggregate_and_database_read_the_same_episodes(vla_eval_run, tmp_path):
    out, _ = vla_eval_run
    from_db = audit(out / "recording-plus.sqlite", tmp_path / "db", "--format=vla_eval")
    from_json = audit(out / "LIBEROPlusBenchmark_aggregate.json", tmp_path / "json", "--format=vla_eval")
    for split in PLANTED:
        assert successes(from_db["splits"][split]) == successes(from_json["splits"][split])
        assert from_db["splits"][split]["lrt"] == from_json["splits"][split]["lrt"]


def test_libero_pro_suites_become_one_perturbation_factor(vla_eval_run, tmp_path):
    _, pro = vla_eval_run
    split = audit(pro, tmp_path, "--format=vla_eval")["splits"]["perturbation"]
    assert successes(split) == {"none": 12, "swap": 0, "env": 12}
    assert split["n_contexts"] == 1 and split["n_episodes"] == 36 and split["p_value"] < 1 / 31
    # the base task as context instead of the base suite
    split = audit(pro, tmp_path, "--format=vla_eval", "--map.context=base_task")["splits"]["perturbation"]
    assert split["n_contexts"] == 3 and successes(split) == {"none": 12, "swap": 0, "env": 12}


def test_vla_eval_results_without_a_perturbation_field_name_the_override(vla_eval_run, tmp_path, capsys):
    out, _ = vla_eval_run
    collector_json = out / "collector.json"
    with pytest.raises(SystemExit):
        audit(collector_json, tmp_path, "--format=vla_eval")
    err = capsys.readouterr().err
    assert "carry no perturbation field: no LIBERO-plus `category`" in err
    assert "Name them with --map.factor=COLUMN --map.value=COLUMN (or --factor_name=NAME)" in err
    metrics = audit(
        collector_json, tmp_path, "--format=vla_eval", "--factor_name=task", "--map.value=task",
        "--map.context=benchmark",
    )  # fmt: skip
    assert sum(successes(metrics["splits"]["task"]).values()) == sum(
        k * len(INSTRUCTIONS) for levels in PLANTED.values() for k in levels.values()
    )
    for bad, message in (
        (next((out / "episodes").rglob("*.jsonl")), "holds one episode's step rows"),
        (tmp_path / "metrics.json", "no vla-eval result (no `tasks` list)"),
    ):
        with pytest.raises(SystemExit):
            audit(bad, tmp_path / "bad", "--format=vla_eval")
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit):
        audit(out, tmp_path, "--format=lerobot")
    assert "--format='lerobot' is not a harness audit reads; known: vla_eval, inspect_robots" in (
        capsys.readouterr().err
    )


# Inspect Robots: factor → value → successes of EPOCHS per context (scene metadata), judged by an operator.
EPOCHS = 6
CONTEXTS = ("tabletop", "shelf", "sink")
INSPECT_PLANTED = {"camera": {"front": 5, "side": 5, "top": 0}, "light": {"dim": 3, "bright": 3}}


@pytest.fixture(scope="module")
def inspect_logs(tmp_path_factory):
    """One Inspect Robots run per factor on its mock CubePick world and scripted policy; an operator's verdict
    (the planted outcome) scores each trial."""
    log_dir = tmp_path_factory.mktemp("inspect")
    for factor, values in INSPECT_PLANTED.items():
        scenes = [
            Scene(
                id=f"{factor}-{value}-{context}",
                instruction="reach the cube",
                init_seed=i,
                metadata={"factor": factor, "value": value, "context": context},
            )
            for i, (value, context) in enumerate((v, c) for v in values for c in CONTEXTS)
        ]

        def judge(record, scene, values=values):
            ok = record.epoch < values[scene.metadata["value"]]
            record.operator_judgement = "success" if ok else "failure"

        task = Task(name=factor, scenes=scenes, scorer=operator_scorer(), max_steps=2, epochs=EPOCHS)
        inspect_eval(
            task, ScriptedPolicy(), CubePickEmbodiment(), log_dir=str(log_dir), before_scoring=judge,
            store_actions=False,
        )  # fmt: skip
    return log_dir


def test_inspect_robots_log_folder_from_the_command_line(inspect_logs, tmp_path):
    done = cli.run(
        "roboview.pipelines.audit",
        "--format=inspect_robots",
        f"--results={inspect_logs}",
        f"--output_dir={tmp_path}",
        *FAST,
    )
    assert done.returncode == 0, done.stderr
    splits = json.loads((tmp_path / "metrics.json").read_text())["splits"]
    assert set(splits) == set(INSPECT_PLANTED)
    for factor, values in INSPECT_PLANTED.items():
        assert successes(splits[factor]) == {v: k * len(CONTEXTS) for v, k in values.items()}
        assert splits[factor]["n_episodes"] == len(values) * len(CONTEXTS) * EPOCHS
        assert splits[factor]["n_contexts"] == len(CONTEXTS)
    assert (
        splits["camera"]["p_value_method"] == "permutation+scaled_chi2_tail"
        and splits["light"]["p_value"] > 0.5
    )
    assert "success ← score.operator" in (tmp_path / "report.md").read_text()


def test_inspect_robots_refuses_another_schema_version_and_names_missing_metadata(
    inspect_logs, tmp_path, capsys
):
    log = json.loads(next(inspect_logs.glob("camera_*.json")).read_text())
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps({**log, "version": 2}))
    with pytest.raises(SystemExit):
        audit(newer, tmp_path / "out", "--format=inspect_robots")
    assert "eval-log schema version 2 is not supported; the installed inspect-robots reads version 1" in (
        capsys.readouterr().err
    )
    for sample in log["samples"]:
        metadata = sample["scene_metadata"]
        sample["scene_metadata"] = {"perturbation": metadata["value"], "context": metadata["context"]}
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(log))
    with pytest.raises(SystemExit):
        audit(bare, tmp_path / "out", "--format=inspect_robots")
    err = capsys.readouterr().err
    assert "the scenes' metadata has no `factor` key (their keys: perturbation, context)" in err
    assert "Name them with --map.factor=COLUMN --map.value=COLUMN (or --factor_name=NAME)" in err
    split = audit(
        bare, tmp_path / "out", "--format=inspect_robots", "--factor_name=camera",
        "--map.value=metadata.perturbation",
    )["splits"]["camera"]  # fmt: skip
    assert successes(split) == {"front": 15, "side": 15, "top": 0} and split["n_episodes"] == 54


# gauntlet-robotics 0.5.1 and xevals 0.1.0 runs, each written by the tool's own writer (tests/fixtures/*/gen_*).
GAUNTLET = ROOT / "tests" / "fixtures" / "gauntlet"
XEVALS = ROOT / "tests" / "fixtures" / "xevals"


def test_gauntlet_episodes_are_audited_with_their_axes_as_the_factor(tmp_path):
    metrics = audit(GAUNTLET, tmp_path, "--format=gauntlet")
    split = metrics["splits"]["object_swap"]
    episodes = json.loads((GAUNTLET / "episodes.json").read_text())
    planted = {}
    for e in episodes:
        value = f"object_swap={e['perturbation_config']['object_swap']:g}"
        planted[value] = planted.get(value, 0) + int(e["success"])
    assert successes(split) == planted == {"object_swap=0": 1, "object_swap=1": 0, "object_swap=2": 0}
    assert split["n_episodes"] == 12 and metrics["policy"] == "scripted"
    text = (tmp_path / "report.md").read_text()
    assert "gauntlet-robotics 0.5.1 episodes episodes.json (12 episodes)" in text


def test_xevals_cells_are_audited_with_the_clean_cell_as_each_perturbations_baseline(tmp_path):
    metrics = audit(XEVALS / "run.json", tmp_path, "--format=xevals")
    split = metrics["splits"]["visual/color_shift"]
    assert successes(split) == {"0": 4, "0.4": 2, "0.8": 0} and split["n_episodes"] == 12
    # xevals calls a difference significant when 95 % intervals do not overlap; 12 episodes do not separate these.
    assert split["p_value"] > 0.05 and metrics["policy"] == "CallablePolicy"


def test_malformed_gauntlet_and_xevals_files_get_one_line(tmp_path, capsys):
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"summary": {}}))
    episodes = json.loads((GAUNTLET / "episodes.json").read_text())
    lacking = tmp_path / "lacking.json"
    lacking.write_text(json.dumps([{k: v for k, v in e.items() if k != "success"} for e in episodes]))
    run = json.loads((XEVALS / "run.json").read_text())
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps(run | {"schema": 2}))
    for path, fmt, message in (
        (
            report,
            "gauntlet",
            "is a JSON object (gauntlet's report.json is one); expected gauntlet's episodes.json",
        ),
        (lacking, "gauntlet", "episode 0 lacks success;"),
        (newer, "xevals", "xevals run schema 2 is not supported; this reader knows schema 1"),
        (GAUNTLET / "episodes.json", "xevals", "is JSON but no xevals run (no schema, suite and cells)"),
    ):
        with pytest.raises(SystemExit):
            audit(path, tmp_path / "out", f"--format={fmt}")
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err
