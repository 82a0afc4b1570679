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


@dataclass
class ReplayConfig:
    """`--replay.*`: episodes of a results folder re-run here, drawn at random (`--replay=N` is `--replay.n=N`)."""

    # Episodes to re-run (0: none); unset: as many as the guarantee below needs.
    n: int | None = None
    # Size the sample to catch any forgery of at least this share of the rows (e.g. 0.05; 0: no replay) ...
    detect: float = 0.0
    # ... with at least this probability.
    confidence: float = 0.95

    def size(self) -> int:
        """Episodes to re-run (0: none)."""
        from roboview.eval.verification.replay import replay_size

        if self.n is not None and self.n < 0:
            raise ValueError(f"--replay.n={self.n} must be 0 or more")
        if self.n is not None:
            return self.n
        return replay_size(self.detect, self.confidence) if self.detect else 0


def replay_flag(args: list[str]) -> list[str]:
    """`--replay=N`, the short form of `--replay.n=N`, spelled out for the parser."""
    return [a.replace("--replay=", "--replay.n=", 1) if a.startswith("--replay=") else a for a in args]


def result_entries(results: str) -> list[tuple[str | None, Path]]:
    """`--results=A,B,…` of the commands that read several results: (name or None, path) per entry; NAME=PATH names
    the file's policy."""
    entries = []
    for item in filter(None, (x.strip() for x in results.split(","))):
        name, sep, path = item.partition("=")
        entries.append((name.strip(), Path(path.strip())) if sep and "/" not in name else (None, Path(item)))
    return entries
