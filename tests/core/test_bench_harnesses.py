"""The measurement harnesses (`python -m benchmarks.NAME`, `make bench`) keep working between the runs that use
them: each imports without doing anything, answers --help, names only project code that exists (also in the
functions only a full run reaches), and the statistics ones run their smallest case."""

from __future__ import annotations

import ast
import importlib
import json
import multiprocessing
import os
import re
import shlex
import sys
import threading

import pytest

from tests.helpers import ROOT
from tests.helpers.docs import help_run

pytestmark = pytest.mark.fast

HARNESSES = sorted(p.stem for p in (ROOT / "benchmarks").glob("*.py") if not p.stem.startswith("_"))
PROJECT = ("roboview", "benchmarks")


def test_the_harnesses_are_found():
    assert {"throughput", "interval_coverage", "policy_latency"} <= set(HARNESSES) and len(HARNESSES) >= 20


def test_importing_a_harness_does_nothing(tmp_path, monkeypatch, capfd):
    """No output, no file, no thread or process, no environment variable changed: the work is in `main`."""
    monkeypatch.chdir(tmp_path)
    env, threads, children = dict(os.environ), threading.active_count(), multiprocessing.active_children()
    for name in HARNESSES:
        sys.modules.pop(f"benchmarks.{name}", None)  # imported afresh, whatever an earlier test imported
        importlib.import_module(f"benchmarks.{name}")
    out, err = capfd.readouterr()
    assert (out, err) == ("", "")
    assert list(tmp_path.iterdir()) == []
    # (A library's own first import may set its variables, threadpoolctl's KMP_DUPLICATE_LIB_OK: those the project's
    # code never names are not the harness's doing.)
    ours = "\n".join(p.read_text() for folder in PROJECT for p in (ROOT / folder).rglob("*.py"))
    changed = {k for k in {*env, *os.environ} if env.get(k) != os.environ.get(k)}
    assert not {k for k in changed if k in ours}, changed
    assert threading.active_count() == threads and multiprocessing.active_children() == children


def project_references(name: str) -> list[tuple[int, str, str | None]]:
    """(line, module, name or None) for each project module a harness imports, anywhere in it (functions too), and
    each it runs as `python -m MODULE`."""
    tree = ast.parse((ROOT / "benchmarks" / f"{name}.py").read_text())
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module.startswith(PROJECT):
            found += [(node.lineno, node.module, alias.name) for alias in node.names]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name, None) for a in node.names if a.name.startswith(PROJECT)]
        elif isinstance(node, (ast.List, ast.Tuple, ast.Call)):
            items = node.elts if not isinstance(node, ast.Call) else node.args
            strings = [x.value if isinstance(x, ast.Constant) else None for x in items]
            found += [
                (node.lineno, module, None)
                for flag, module in zip(strings, strings[1:])
                if flag == "-m" and isinstance(module, str) and module.startswith(PROJECT)
            ]
    return found


def missing(module: str, name: str | None) -> bool:
    try:
        imported = importlib.import_module(module)
    except ImportError:
        return True
    if name is None or hasattr(imported, name):
        return False
    try:
        return importlib.util.find_spec(f"{module}.{name}") is None  # a submodule not imported yet
    except ImportError:  # `module` is no package
        return True


@pytest.mark.parametrize("name", HARNESSES)
def test_a_harness_names_only_project_code_that_exists(name):
    """A function moved or renamed elsewhere breaks a harness at the line that imports it, which may run only an
    hour into a full measurement: every project import (function-level ones too) and `-m` module must resolve."""
    refs = project_references(name)
    broken = [f"line {line}: {module}{f' import {what}' if what else ''}" for line, module, what in refs]
    broken = [b for b, (_, module, what) in zip(broken, refs) if missing(module, what)]
    assert not broken, f"benchmarks/{name}.py: {broken}"


def test_the_reference_check_sees_a_function_level_import_and_a_module_run():
    refs = project_references("throughput")
    assert (59, "benchmarks.throughput", None) in refs  # [sys.executable, "-m", "benchmarks.throughput", …]
    assert any(module == "roboview.pipelines.build_benchmark" and what == "run" for _, module, what in refs)
    assert missing("roboview.pipelines.build_benchmark", "no_such_function")
    assert missing("roboview.no_such_module", None) and not missing("roboview.pipelines", "evaluate")


@pytest.mark.parametrize("name", HARNESSES)
def test_a_harness_answers_help(name):
    proc = help_run(f"benchmarks.{name}")
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert proc.stdout.startswith("usage:") and name in proc.stdout.splitlines()[0]
    assert re.search(r"^  --\w", proc.stdout, re.M) and "Traceback" not in proc.stderr


# The statistics harnesses (no rendering, training or servers) at their smallest: arguments, then what the output
# must hold.
SMALLEST = {
    # Exact coverage: Wilson's and Clopper–Pearson's at n = 5, p = 0.5, and their least over p.
    "interval_coverage": (
        ["--sizes=5", "--rates=0.5", "--pairs=5"],
        ["| 5 | 0.938 / 1.000 | 0.832 / 0.975 |"],
    ),
    "stats_calibration": (
        ["--sims=2", "--values=3", "--contexts=2", "--repeats=2", "--taus=0"],
        ["3 values × 2 contexts × 2 repeats, SR ≈ 0.7, 2 simulated tables per τ"],
    ),
    "cv_excess_interval": (["--reps=1", "--boot=2", "--values=2", "--contexts=2"], ["| 0.6 | 10 |"]),
    "paired_compare": (["--sims=2", "--pairs=2", "--max_repeats=2"], ["| 0.2 |"]),
    "glm_refits": (["--draws=2", "--statsmodels_draws=1"], ["| 9 × 4 × 5 |", "| 21 × 11 × 3 |"]),
    "adaptive": (["--sims=10", "--designs=2x2x2"], ["[adaptive] 2×2: type-I "]),
}


@pytest.mark.parametrize("name", sorted(SMALLEST))
def test_a_statistics_harness_runs_its_smallest_case(name, tmp_path, capsys):
    args, expected = SMALLEST[name]
    output = tmp_path / "out.json"
    module = importlib.import_module(f"benchmarks.{name}")
    module.main([*args, *([f"--output={output}"] if name == "adaptive" else [])])
    out = capsys.readouterr().out
    assert all(line in out for line in expected), out
    if name == "glm_refits":  # the batched solver's statistics are statsmodels' to solver precision
        diffs = [float(row.split("|")[-2]) for row in out.splitlines() if re.match(r"\| \d", row)]
        assert len(diffs) == 2 and max(diffs) < 1e-6, out
    if name == "adaptive":
        design = json.loads(output.read_text())["designs"][0]
        assert (design["values"], design["contexts"], design["max_repeats"]) == (2, 2, 2)
        assert all(0 <= r["rejection_rate"] <= 1 for r in design["adaptive"].values())


def test_make_bench_runs_a_harness_with_flags_it_takes():
    """`make bench`'s command and the BENCH_ARGS its comment offers parse; each phase the harness runs in a process
    of its own is one it knows, with flags its phase config takes."""
    from roboview.core.cli import parse

    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^bench:.*\n\t(.+)$", makefile, re.M).group(1)
    words = shlex.split(recipe.replace("$(PY)", "python").replace("$(BENCH_ARGS)", ""))
    assert words[:3] == ["python", "-m", "benchmarks.throughput"], recipe
    throughput = importlib.import_module("benchmarks.throughput")
    cfg = parse(throughput.ThroughputConfig, [*words[3:], "--quick=true"])
    assert (cfg.output, cfg.quick) == ("outputs/bench/throughput.json", True)
    assert "BENCH_ARGS=--quick=true" in makefile

    source = (ROOT / "benchmarks" / "throughput.py").read_text()
    calls = [
        n
        for n in ast.walk(ast.parse(source))
        if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "_child"
    ]
    flags = [
        (a.value if isinstance(a, ast.Constant) else a.values[0].value).split("=", 1)
        for call in calls
        for a in call.args
        if isinstance(a, (ast.Constant, ast.JoinedStr))
    ]
    known = set(throughput.PhaseConfig.__dataclass_fields__)
    phases = {value for flag, value in flags if flag == "--phase"}
    assert len(calls) >= 6 and {"build", "render", "collect", "eval", "lerobot_eval", "breakdown"} <= phases
    assert {flag[2:] for flag, _ in flags} <= known, {flag for flag, _ in flags} - {f"--{k}" for k in known}
    assert all(f'args.phase == "{phase}"' in source for phase in phases)
