"""What a new user meets in the first hour: rerunning keeps the Rerun recording, no silent default policy (and the
privileged expert is labelled so), one-line errors for paths that are not what a command reads, a training run
folder answered with the checkpoint to pass, and README / getting-started commands that run in the order shown."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT
from tests.helpers.docs import bash_commands

pytestmark = pytest.mark.slow

RERUN = Path(sys.executable).parent / "rerun"
FAST_REPORT = ["--plots=false", "--metrics.n_perm=50", "--metrics.n_glm=20"]


def _evaluate(bench: Path, out: Path, *flags: str) -> None:
    from roboview.pipelines.evaluate import main

    main(
        [
            f"--benchmark.path={bench}",
            "--policy.type=expert",
            "--benchmark.splits=dist_scale",
            "--eval.n_repeats=1",
            "--eval.num_workers=1",
            f"--output_dir={out}",
            *flags,
        ]
    )


def _one_line_error(capsys, call, *args) -> str:
    """`call(args)` exits with status 2 and one line on stderr; that line."""
    with pytest.raises(SystemExit) as exit_:
        call(list(args))
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2, err
    assert err.startswith("error: ") and len(err.splitlines()) == 1, err
    return err


@pytest.fixture(scope="module")
def evaluated(tiny_benchmark, tmp_path_factory) -> Path:
    """The expert on 2 dist_scale instances: a results folder (run.json, episodes.jsonl, episodes.parquet)."""
    out = tmp_path_factory.mktemp("first_hour") / "expert"
    _evaluate(tiny_benchmark, out, "--eval.limit=2")
    return out


# -- 1. a rerun never loses the Rerun recording ----------------------------------------------------------------


def test_rerunning_keeps_every_rerun_recording(tiny_benchmark, tmp_path, capsys):
    rrd = tmp_path / "rec" / "vision.rrd"
    out = tmp_path / "ev"
    _evaluate(tiny_benchmark, out, "--eval.limit=1", f"--eval.rerun={rrd}")
    first = rrd.read_bytes()
    assert len(first) > 10_000
    summaries = [capsys.readouterr().out]
    # The same command again: nothing new to run, nothing written, the recording untouched.
    _evaluate(tiny_benchmark, out, "--eval.limit=1", f"--eval.rerun={rrd}")
    assert rrd.read_bytes() == first and sorted(p.name for p in rrd.parent.iterdir()) == ["vision.rrd"]
    summaries.append(capsys.readouterr().out)
    # More episodes: they go to vision-2.rrd, the first recording still untouched.
    _evaluate(tiny_benchmark, out, "--eval.limit=2", f"--eval.rerun={rrd}")
    second = rrd.with_name("vision-2.rrd")
    assert rrd.read_bytes() == first and second.is_file() and len(second.read_bytes()) > 10_000
    summaries.append(capsys.readouterr().out)
    proc = subprocess.run(
        [str(RERUN), "rrd", "verify", str(rrd), str(second)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # Each run's summary names every recording of the path, to open together.
    assert f"rerun {rrd}\n" in summaries[0] and f"rerun {rrd}\n" in summaries[1], summaries
    assert f"rerun {rrd} {second}\n" in summaries[2], summaries


# -- 2. --policy.type is required; the expert is labelled privileged -------------------------------------------


def test_policy_type_is_required(tmp_path, capsys):
    from roboview.pipelines.evaluate import main as evaluate
    from roboview.pipelines.serve_policy import main as serve

    for call, args in (
        (evaluate, [f"--benchmark.path={tmp_path}", f"--output_dir={tmp_path / 'out'}"]),
        (evaluate, [f"--benchmark.path={tmp_path}", "--policy.name=mine"]),
        (serve, ["--port=0"]),
    ):
        err = _one_line_error(capsys, call, *args)
        assert "--policy.type is required" in err and "vision" in err and "lerobot" in err, err
        assert "`expert` is the privileged scripted expert" in err and "simulator state" in err, err
    assert not (tmp_path / "out").exists()


def test_the_expert_is_labelled_privileged_in_the_summary_and_the_report(
    evaluated, tiny_benchmark, tmp_path, capsys
):
    from roboview.pipelines.report import main as report

    _evaluate(tiny_benchmark, evaluated, "--eval.limit=2")  # resumes: nothing new, the summary line again
    line = capsys.readouterr().out
    assert "2 episodes of expert (privileged" in line and "simulator state" in line, line

    report([f"--results={evaluated}/episodes.parquet", f"--output_dir={tmp_path / 'rep'}", *FAST_REPORT])
    md = (tmp_path / "rep" / "report.md").read_text()
    summary = md.split("## Summary", 1)[1].split("\n## ", 1)[0]
    assert "| expert (privileged) |" in summary and "reads the simulator state" in summary
    assert "expert (privileged)" in (tmp_path / "rep" / "report.html").read_text()


# -- 3. one-line errors for paths that are not what a command reads --------------------------------------------


@pytest.fixture()
def not_results(evaluated, tiny_benchmark, tmp_path) -> dict[str, Path]:
    (tmp_path / "rollouts.csv").write_text("task,variant,success\na,b,1\n")
    (tmp_path / "random.bin").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "random.parquet").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "empty").mkdir()
    return {
        "journal": evaluated / "episodes.jsonl",
        "benchmark": tiny_benchmark,
        "table": tiny_benchmark / "data" / "dist_scale.parquet",
        "csv": tmp_path / "rollouts.csv",
        "bytes": tmp_path / "random.bin",
        "fake_parquet": tmp_path / "random.parquet",
        "folder": tmp_path / "empty",
        "missing": tmp_path / "nowhere.parquet",
    }


REPORT_EXPECTS = {
    "journal": "the journal",
    "benchmark": "is a benchmark folder",
    "table": "a table of the benchmark",
    "csv": "is a CSV file",
    "bytes": "is not a parquet file",
    "fake_parquet": "bytes are not parquet",
    "folder": "holds no results",
    "missing": "not found",
}


def test_report_names_every_input_that_is_not_results(evaluated, not_results, tmp_path, capsys):
    from roboview.pipelines.report import main as report

    for kind, path in not_results.items():
        err = _one_line_error(capsys, report, f"--results={path}", f"--output_dir={tmp_path / 'rep'}")
        assert str(path) in err and REPORT_EXPECTS[kind] in err, (kind, err)
        assert "episodes.parquet" in err, (kind, err)  # what is expected
    journal = _one_line_error(capsys, report, f"--results={not_results['journal']}")
    assert f"pass {evaluated / 'episodes.parquet'}" in journal
    assert "--benchmark.path=" in _one_line_error(capsys, report, f"--results={not_results['benchmark']}")
    # A results folder stands for its episodes.parquet.
    result = report([f"--results={evaluated}", f"--output_dir={tmp_path / 'rep'}", *FAST_REPORT])
    assert result.metrics["sources"][0]["path"] == str(evaluated / "episodes.parquet")


def test_audit_verify_and_merge_name_every_input_that_is_not_theirs(
    evaluated, not_results, tiny_benchmark, tmp_path, capsys
):
    from roboview.pipelines.audit import main as audit
    from roboview.pipelines.merge import main as merge
    from roboview.pipelines.verify import main as verify

    mapping = [
        "--map.factor=task",
        "--map.value=variant",
        "--map.context=task",
        "--map.success=success",
        f"--output_dir={tmp_path / 'audit'}",
    ]
    (tmp_path / "bad.csv").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "empty.csv").write_text("")
    for path, expected in (
        (tiny_benchmark, "is a benchmark folder"),
        (evaluated, "roboview-report"),
        (not_results["bytes"], "unknown format '.bin'"),
        (not_results["folder"], "is a folder"),
        (not_results["fake_parquet"], "bytes are not parquet"),
        (tmp_path / "bad.csv", "could not be read as CSV"),
        (tmp_path / "empty.csv", "as CSV"),
        (not_results["missing"], "no such file"),
    ):
        err = _one_line_error(capsys, audit, f"--results={path}", *mapping)
        assert str(path) in err and expected in err, err
        assert "expected one row per episode" in err or "roboview-report" in err, err

    for path, expected in (
        (not_results["journal"], f"pass the folder, {evaluated}"),
        (evaluated / "episodes.parquet", f"pass the folder, {evaluated}"),
        (tiny_benchmark, f"--benchmark.path={tiny_benchmark}"),
        (not_results["csv"], "is a file, not a folder"),
        (not_results["folder"], "run.json missing"),
        (not_results["missing"], "does not exist"),
    ):
        err = _one_line_error(capsys, verify, f"--results={path}")
        assert str(path) in err and expected in err, err
    for path, expected in (
        (evaluated, f"--results={evaluated}"),
        (not_results["table"], f"folder, {tiny_benchmark}"),
        (not_results["folder"], "benchmark.json missing"),
    ):
        err = _one_line_error(capsys, verify, f"--benchmark.path={path}")
        assert str(path) in err and expected in err, err
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "run.json").write_text((evaluated / "run.json").read_text())
    (broken / "episodes.parquet").write_bytes(bytes(range(256)) * 8)
    assert "bytes are not parquet" in _one_line_error(capsys, verify, f"--results={broken}")

    for path, expected in (
        (evaluated / "episodes.parquet", f"pass the folder, {evaluated}"),
        (tiny_benchmark, "is a benchmark folder"),
        (not_results["csv"], "is a file, not a folder"),
        (not_results["folder"], "run.json missing"),
        (broken, "bytes are not parquet"),
    ):
        err = _one_line_error(
            capsys, merge, f"--results={path},{evaluated}", f"--output_dir={tmp_path / 'merged'}"
        )
        assert str(path) in err and expected in err, err
    assert not (tmp_path / "merged").exists()


# -- 4. a training run folder as --policy.path -----------------------------------------------------------------


def test_a_training_run_folder_names_the_checkpoint_to_pass(tmp_path, capsys):
    from roboview.policies.checkpoints import CheckpointError, checkpoint_dir

    run = tmp_path / "train_act96"
    for step in ("000002", "000004", "last"):
        (run / "checkpoints" / step / "pretrained_model").mkdir(parents=True)
        (run / "checkpoints" / step / "pretrained_model" / "config.json").write_text("{}")
    last = run / "checkpoints" / "last" / "pretrained_model"
    for given in (run, run / "checkpoints"):
        with pytest.raises(CheckpointError) as refused:
            checkpoint_dir(str(given))
        message = str(refused.value)
        assert f"--policy.path={last} " in message and "other checkpoints: 000004, 000002" in message, message
    assert checkpoint_dir(str(run / "checkpoints" / "last")) == last  # a checkpoint folder is still accepted
    assert checkpoint_dir(str(last)) == last
    with pytest.raises(CheckpointError, match="holds no LeRobot checkpoint"):
        checkpoint_dir(str(tmp_path))
    # Through the command line: one line, with the exact path.
    from roboview.pipelines.evaluate import main as evaluate

    err = _one_line_error(
        capsys, evaluate, f"--benchmark.path={tmp_path}", "--policy.type=lerobot", f"--policy.path={run}"
    )
    assert f"--policy.path={last}" in err


# -- 5. the README's and getting-started's commands run in the order shown -------------------------------------


def _value(args: list[str], flag: str) -> str | None:
    return next((a.split("=", 1)[1] for a in args if a.startswith(flag + "=")), None)


@pytest.mark.parametrize("page", ["README.md", "docs/getting-started.md"])
def test_every_benchmark_a_command_reads_is_built_by_a_command_before_it(page):
    built: set[str] = set()
    demo = False
    unbuilt = []
    for line, command in bash_commands(ROOT / page):
        try:
            words = shlex.split(command.split(" # ")[0])
        except ValueError:
            continue
        demo |= words[:2] == ["make", "demo"]
        for flag in ("--benchmark.path", "--env.benchmark_path", "--path"):
            path = _value(words, flag)
            if path and not (path in built or (demo and path.startswith("outputs/demo/"))):
                unbuilt.append(f"{page}:{line}: {flag}={path} before any command builds it")
        if "roboview.pipelines.build_benchmark" in words or any(
            w.endswith("roboview-build-benchmark") for w in words
        ):
            built.add(_value(words, "--output_dir") or "outputs/benchmark")
    assert not unbuilt, "\n".join(unbuilt)
