"""Console scripts (`pyproject.toml` [project.scripts]), as lerobot ships `lerobot-train` / `lerobot-eval`.

    roboview-collect   = python -m pipelines.collect
    roboview-build     = python -m pipelines.build_benchmark
    roboview-eval      = python -m pipelines.evaluate
    roboview-report    = python -m pipelines.report
    roboview-publish   = python -m pipelines.publish
    roboview-train     = python -m pipelines.train

Each takes the same flags as its module. The wrappers drop the pipeline's return value: a console script
exits with `sys.exit(main())`, and a returned object would become exit status 1.
"""

from __future__ import annotations

import importlib


def _run(module: str) -> None:
    importlib.import_module(module).main()


def collect() -> None:
    _run("pipelines.collect")


def build() -> None:
    _run("pipelines.build_benchmark")


def evaluate() -> None:
    _run("pipelines.evaluate")


def report() -> None:
    _run("pipelines.report")


def publish() -> None:
    _run("pipelines.publish")


def train() -> None:
    _run("pipelines.train")
