"""Episode tables written as `roboview-evaluate` writes them, without a simulator: every column for the tiny suite's
instances, outcomes seeded per policy (the report, board and infrastructure-error tests read them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from roboview.eval.reporting.report import VERSION_KEY
from roboview.eval.running.results import FORMAT_KEY
from roboview.eval.statistics.metrics import MetricsConfig
from roboview.tasks import load_preset
from roboview.variation.instances import episode_seed, generate_suite

# Report settings that keep a report to seconds: fewer GLM refits and permutations.
FAST = {"metrics": MetricsConfig(n_glm=20, n_perm=50)}


def make_episodes(
    policy: str, seed: int, splits: tuple[str, ...] | None = None, repeats: int = 3
) -> pd.DataFrame:
    """Every episode column (docs/formats.md) for the tiny suite's instances; outcomes seeded per policy."""
    rng = np.random.default_rng(seed)
    rows = []
    for instance in generate_suite(load_preset("tiny")):
        if splits is not None and instance.split not in splits:
            continue
        record = instance.to_record()
        p = rng.random()
        for r in range(repeats):
            success = bool(rng.random() < p)
            rows.append(
                {
                    **record,
                    "repeat": r,
                    "episode_seed": episode_seed(record["context_id"], r),
                    "cameras": [
                        {"name": "front", "pos": [0.0, 0.0, 1.0], "quat": [1.0, 0.0, 0.0, 0.0], "fovy": 45.0}
                    ],
                    "success": success,
                    "steps": 10,
                    "duration_s": 0.1,
                    "policy": policy,
                    "failure_reason": "" if success else "timeout",
                }
            )
    return pd.DataFrame(rows)


def write(
    frame: pd.DataFrame, path: Path, version: str | None = "tiny-abc", results_format: bytes = b"2"
) -> Path:
    table = pa.Table.from_pandas(frame)
    table = table.replace_schema_metadata({**table.schema.metadata, FORMAT_KEY: results_format})
    if version is not None:
        table = table.replace_schema_metadata(
            {**table.schema.metadata, VERSION_KEY.encode(): version.encode()}
        )
    pq.write_table(table, path)
    return path
