"""The one folder guard every command's input and output folders go through (roboview.core.folders)."""

from __future__ import annotations

import pytest

from roboview.core.folders import folder_problem

pytestmark = pytest.mark.fast


def test_a_folder_being_written_may_be_new_empty_or_marked(tmp_path):
    def problem(path):
        return folder_problem(
            path, "benchmark", "benchmark.json", "choose a new folder", label=f"--out={path}", writing=True
        )

    assert problem(tmp_path / "new") is None
    assert problem(tmp_path) is None  # empty
    (tmp_path / "other.txt").write_text("x")
    assert problem(tmp_path) == (
        f"--out={tmp_path} is not empty and holds no RoboView benchmark "
        "(benchmark.json missing); choose a new folder"
    )
    (tmp_path / "benchmark.json").write_text("{}")
    assert problem(tmp_path) is None  # an earlier build: resumed or replaced
    file = tmp_path / "other.txt"
    assert problem(file) == f"--out={file} is a file, not a folder; choose a new folder"


def test_a_folder_being_read_must_exist_and_be_marked(tmp_path):
    def problem(path):
        return folder_problem(path, "results", "run.json", "give a results folder")

    assert problem(tmp_path / "missing") == f"{tmp_path / 'missing'} does not exist; give a results folder"
    expected = f"{tmp_path} holds no RoboView results (run.json missing); give a results folder"
    assert problem(tmp_path) == expected
    (tmp_path / "run.json").write_text("{}")
    assert problem(tmp_path) is None
    assert problem(tmp_path / "run.json").startswith(f"{tmp_path / 'run.json'} is a file, not a folder")


@pytest.mark.parametrize("reader", ["results", "benchmark"])
def test_the_commands_guards_say_the_same(tmp_path, reader):
    from roboview.benchmark.format import BenchmarkError, read_manifest
    from roboview.eval.running.inputs import benchmark_folder_problem, results_folder_problem

    check = results_folder_problem if reader == "results" else benchmark_folder_problem
    marker = "run.json" if reader == "results" else "benchmark.json"
    assert check(tmp_path).startswith(f"{tmp_path} holds no RoboView {reader} ({marker} missing); expected a")
    (tmp_path / "x.csv").write_text("a\n")
    file = tmp_path / "x.csv"
    assert check(file).startswith(f"{file} is a file, not a folder; expected a")
    with pytest.raises(BenchmarkError, match=r"no RoboView benchmark \(benchmark.json missing\); build one"):
        read_manifest(tmp_path)
