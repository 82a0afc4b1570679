"""Read a frozen benchmark folder back into task instances (without previews or fairness data)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pyarrow.parquet as pq

from roboview_data.benchmark.format import FORMAT_VERSION, MANIFEST
from roboview_data.variation.factors import FACTOR_NAMES
from roboview_data.variation.instances import CONTEXT_SUBSPACES, TaskInstance

# Instance columns that travel into every episode row (DESIGN.md: all but fairness and preview).
EPISODE_INSTANCE_COLUMNS = ("instance_id", "split", "factor", "value", "context_id", *FACTOR_NAMES,
                            "color_hex", "color_rgb", "color_lab", "cameras", "seed")


@dataclass(frozen=True)
class BenchmarkItem:
    instance: TaskInstance
    record: dict  # the EPISODE_INSTANCE_COLUMNS of its row


@dataclass(frozen=True)
class Benchmark:
    path: Path
    version: str
    splits: dict[str, list[BenchmarkItem]]


def _instance_from_record(record: dict) -> TaskInstance:
    """Rebuild the instance; its id must reproduce the stored one (else the row was edited)."""
    factors = {name: record[name] for name in FACTOR_NAMES}
    varied = tuple(record["factor"].split("|"))
    for subspace in CONTEXT_SUBSPACES:
        instance = TaskInstance(record["split"], varied, factors, subspace)
        if instance.instance_id == record["instance_id"]:
            return instance
    raise ValueError(f"benchmark row {record['instance_id']} does not hash to its id: the split was "
                     "modified after it was built; rebuild it with pipelines.build_benchmark")


def load_benchmark(path: str | Path, splits: list[str] | None = None) -> Benchmark:
    root = Path(path)
    manifest_path = root / MANIFEST
    if not manifest_path.is_file():
        raise ValueError(f"--benchmark.path={root} holds no RoboView benchmark ({MANIFEST} missing); "
                         "build one with `python -m pipelines.build_benchmark`")
    manifest = json.loads(manifest_path.read_text())
    if manifest.get("format") != FORMAT_VERSION:
        raise ValueError(f"--benchmark.path={root} has benchmark format {manifest.get('format')!r}; this version "
                         f"reads format {FORMAT_VERSION} (episode seeds shared per context and repeat); rebuild it "
                         "with `python -m pipelines.build_benchmark`")
    if manifest.get("status") != "ok":
        raise ValueError(f"--benchmark.path={root} is a failed build; rebuild it")
    available = [s for s in manifest["splits"] if (root / "data" / f"{s}.parquet").is_file()]
    chosen = splits or available
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise ValueError(f"unknown split(s) {unknown} in --benchmark.splits; this benchmark has: "
                         f"{', '.join(available)}")
    out: dict[str, list[BenchmarkItem]] = {}
    for split in chosen:
        table = pq.read_table(root / "data" / f"{split}.parquet", columns=list(EPISODE_INSTANCE_COLUMNS))
        out[split] = [BenchmarkItem(_instance_from_record(row), row) for row in table.to_pylist()]
    return Benchmark(root, manifest["benchmark_version"], out)
