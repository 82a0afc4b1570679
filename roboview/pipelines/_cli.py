"""The pipelines' command-line layer: `roboview.core.cli` (parsing, `--help`, errors, Ctrl-C, the one `main`
helper) and the flag groups the pipelines share."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

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


def result_entries(results: str) -> list[tuple[str | None, Path]]:
    """`--results=A,B,…` of the commands that read several results: (name or None, path) per entry; NAME=PATH names
    the file's policy."""
    entries = []
    for item in filter(None, (x.strip() for x in results.split(","))):
        name, sep, path = item.partition("=")
        entries.append((name.strip(), Path(path.strip())) if sep and "/" not in name else (None, Path(item)))
    return entries
