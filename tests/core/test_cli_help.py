"""Every entry point answers --help and documents every field of its config as a flag."""

import dataclasses
import importlib
import re
import typing
from pathlib import Path

import draccus
import pytest

from roboview.pipelines._console import VERBS
from tests.helpers import cli
from tests.helpers.docs import help_run

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
# The verbs: one module in roboview/pipelines/ and one console script each (declared in _console.VERBS).
ENTRY_POINTS = VERBS


# The LeRobot side's own commands.
LEROBOT_SIDE = ("roboview.integrations.lerobot.convert", "roboview.integrations.lerobot.tiny_vla")
# The vla-eval side's own command.
VLA_EVAL_SIDE = ("roboview.integrations.vla_eval.convert",)
# The measurement harnesses (`make bench` and the figures in docs/performance.md).
HARNESSES = (
    "adaptive",
    "cluster",
    "collect_rate",
    "conformance_drift",
    "cv_excess_interval",
    "glm_refits",
    "interval_coverage",
    "gpu",
    "libero_expert",
    "libero_render",
    "libero_throughput",
    "libero_vs_lerobot_eval",
    "libero_plus_poses",
    "libero_plus_noise_cost",
    "metaworld_expert",
    "metaworld_vs_lerobot_eval",
    "paired_compare",
    "render_rate",
    "serving",
    "stats_calibration",
    "throughput",
    "verify_rate",
)
# Harnesses that run where RoboView's dependencies are absent (a GPU machine given only the simulator or only torch):
# plain argparse, so only their --help is checked.
STANDALONE = ("libero_render_rate", "policy_latency")


@pytest.mark.parametrize(
    "module",
    [f"roboview.pipelines.{name}" for name in ENTRY_POINTS]
    + list(LEROBOT_SIDE)
    + list(VLA_EVAL_SIDE)
    + [f"benchmarks.{name}" for name in HARNESSES],
)
def test_help_documents_the_flags(module):
    proc = help_run(module)
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert "usage:" in proc.stdout and "Traceback" not in proc.stderr
    config = _config_class(module)
    if config is not None:
        missing = [
            flag for flag in config_flags(config) if not re.search(rf"{re.escape(flag)}\b", proc.stdout)
        ]
        assert not missing, f"{module} --help lacks {missing}"
    # Every flag shown has its own description and its default (or says it is required), each flag is shown
    # once per section, and the flags shown are exactly those the command accepts.
    shown = help_flags(proc.stdout)
    assert shown, proc.stdout[:500]
    undocumented = [
        flag for flag, text in shown if not re.sub(r"\((default: [^)]*|required)\)$", "", text).strip()
    ]
    no_default = [flag for flag, text in shown if not re.search(r"\((default: .+|required)\)$", text)]
    assert not undocumented, f"{module} --help: no description for {undocumented}"
    assert not no_default, f"{module} --help: no default for {no_default}"
    assert "Config file for" not in proc.stdout and proc.stdout.count("--config_path") == 1
    if config is not None:
        assert {flag for flag, _ in shown} == accepted_flags(config), module


def help_flags(text: str) -> list[tuple[str, str]]:
    """(flag, its description with its default) for every flag line of a --help text (except -h, --help)."""
    found: list[list[str]] = []
    for line in text.splitlines():
        if line.startswith("  -"):  # a flag: its description from column 24 on, or on the lines below
            found.append([line.split()[0].rstrip(","), line[24:] if line[22:24] == "  " else ""])
        elif line.startswith(" " * 24) and found:
            found[-1][1] += " " + line.strip()
        elif not line.strip() and found:
            found.append(["", ""])  # a section ends
    return [(flag, " ".join(text.split())) for flag, text in found if flag and flag != "-h"]


def accepted_flags(config: type) -> set[str]:
    """The flags draccus's parser of `config` accepts (less the per-section config-file ones)."""
    from draccus.argparsing import ArgumentParser

    from roboview.policies.types import load_policy_types

    load_policy_types()  # as a command does before it parses: every --policy.type's flags
    actions = ArgumentParser(config_class=config).parser._option_string_actions
    return {
        name
        for name, action in actions.items()
        if name not in ("-h", "--help") and not (action.help or "").startswith("Config file for")
    }


def _config_class(module: str) -> type | None:
    """The config dataclass a module hands to cli_main (None for a module that parses otherwise)."""
    source = Path(importlib.util.find_spec(module).origin).read_text()
    found = re.search(r"cli_main\(\s*(\w+)", source)
    return getattr(importlib.import_module(module), found.group(1)) if found else None


def config_flags(config: type, prefix: str = "") -> list[str]:
    """Every --flag a draccus config declares: its fields, nested dataclasses' fields as --a.b (a choice registry,
    such as --policy, contributes its own `type` flag)."""
    hints = typing.get_type_hints(config)
    flags = []
    for f in dataclasses.fields(config):
        kind = hints.get(f.name)
        if isinstance(kind, type) and issubclass(kind, draccus.ChoiceRegistry):
            flags.append(f"--{prefix}{f.name}.type")
        elif isinstance(kind, type) and dataclasses.is_dataclass(kind):
            flags += config_flags(kind, f"{prefix}{f.name}.")
        else:
            flags.append(f"--{prefix}{f.name}")
    return flags


def test_config_flags_walks_nested_configs():
    from roboview.pipelines.evaluate import EvaluateConfig
    from roboview.pipelines.report import ReportConfig

    flags = config_flags(EvaluateConfig)
    assert {"--benchmark.path", "--eval.shard", "--eval.n_repeats", "--policy.type", "--output_dir"} <= set(
        flags
    )
    assert config_flags(ReportConfig)[:2] == ["--results", "--output_dir"]


def test_every_pipeline_module_is_covered():
    modules = {p.stem for p in (ROOT / "roboview" / "pipelines").glob("*.py") if not p.stem.startswith("_")}
    assert modules == set(ENTRY_POINTS)
    harnesses = {p.stem for p in (ROOT / "benchmarks").glob("*.py") if not p.stem.startswith("_")}
    assert harnesses == set(HARNESSES) | set(STANDALONE)
    # Each parses with the one command-line helper (its --help then lists every flag, checked above).
    assert all(_config_class(f"benchmarks.{name}") is not None for name in HARNESSES)


@pytest.mark.parametrize("name", STANDALONE)
def test_standalone_harnesses_explain_their_flags(name):
    proc = help_run(f"benchmarks.{name}")
    assert proc.returncode == 0 and "usage:" in proc.stdout, proc.stderr[-1500:]
    flags = [flag for flag, _ in help_flags(proc.stdout)]
    assert "--output" in flags and all(text for _, text in help_flags(proc.stdout)), proc.stdout


def test_lists_are_written_comma_separated_everywhere():
    from roboview.pipelines._cli import parse
    from roboview.pipelines.build_benchmark import BuildConfig

    cfg = parse(BuildConfig, ["--factorial_colors=red,blue", "--cartesian=[color,shape]"])
    # brackets still read
    assert cfg.factorial_colors == ["red", "blue"] and cfg.cartesian == ["color", "shape"]
    proc = cli.run(
        "roboview.pipelines.collect",
        "--dataset.repo_id=t/x",
        "--dataset.root=/nonexistent/roboview-test",
        "--dataset.cameras=left_top,nope",
        timeout=120,
    )
    assert proc.returncode != 0 and "nope" in proc.stderr  # the list was read: its bad entry is named


def test_every_documented_flag_exists():
    """Every flag the README and docs/ pass to a RoboView command is one its --help documents (checked here, where
    each module's --help has already run once)."""
    from tests.helpers.docs import documented_flag_problems

    wrong = documented_flag_problems()
    assert not wrong, "\n".join(wrong)


def test_importing_a_harness_leaves_the_environment_as_it_was():
    """A harness sets its rendering and thread variables where it runs (its `main`), not on import: a program that
    imports it, as this file does to read its --help, keeps its own (tests/helpers/cli.py: a test process whose
    import-time variables changed would start every later command-line run from a fresh interpreter)."""
    import os

    before = dict(os.environ)
    for name in (*HARNESSES, *STANDALONE):
        importlib.import_module(f"benchmarks.{name}")
    threads = {
        k for k in {*before, *os.environ} if k.endswith("_NUM_THREADS") and before.get(k) != os.environ.get(k)
    }
    assert not threads and not cli.import_time_changes(os.environ), threads
