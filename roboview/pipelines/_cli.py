"""The pipelines' command-line layer: `roboview.core.cli` (parsing, `--help`, errors, Ctrl-C, the one `main`
helper) and the flag groups the pipelines share."""

from __future__ import annotations

from dataclasses import dataclass

from roboview.core.cli import (  # noqa: F401  (the pipelines import the command-line helpers from here)
    cli_main,
    interrupted,
    parse,
    setup_environment,
)
from roboview.core.cli_help import format_help  # noqa: F401


@dataclass
class BenchmarkPath:
    """`--benchmark.path`: the one spelling of a benchmark folder across RoboView's commands."""

    # Benchmark folder written by roboview.pipelines.build_benchmark.
    path: str = ""
