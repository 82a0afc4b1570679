"""An evaluation in-process, as `roboview-evaluate` runs one (the expert by default, on the tiny benchmark's splits),
and its rows read back in a fixed order."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
from roboview.eval.campaign.runner import run
from roboview.eval.running.results import PARQUET
from roboview.policies.types import policy_config


def evaluate(
    bench: Path,
    out: Path,
    policy: str = "expert",
    splits: str = "",
    limit: int = 2,
    repeats: int = 1,
    backend: str = "local",
    workers: int = 2,
    rerun: str = "",
    path: str | None = None,
    max_steps: int = 120,
    image_size: int = 64,
    envs_per_worker: int = 1,
    videos: str = "",
    eager: bool = False,
    policy_server: bool = False,
    torch_threads: int = 0,
):
    """roboview.eval.campaign.runner.run of `policy` (a type name) over `splits` of `bench` into `out`."""
    cfg = EvaluateConfig(
        BenchmarkConfig(str(bench), splits),
        policy_config(policy, **({"path": path} if path else {})),
        EvalConfig(
            n_repeats=repeats,
            limit=limit,
            num_workers=workers,
            backend=backend,
            rerun=rerun,
            image_size=image_size,
            max_steps=max_steps,
            envs_per_worker=envs_per_worker,
            videos=videos,
            eager_render=eager,
            policy_server=policy_server,
            torch_threads=torch_threads,
        ),
        str(out),
    )
    return run(cfg)


def rows(out: Path) -> pd.DataFrame:
    """The results' episodes (but their wall-clock durations) sorted by instance and repeat."""
    return (
        pd.read_parquet(Path(out) / PARQUET)
        .drop(columns=["duration_s"])
        .sort_values(["instance_id", "repeat"])
        .reset_index(drop=True)
    )
