"""The frozen benchmark folder — written and read here, nowhere else.

A benchmark is a Hugging Face dataset folder:

    benchmark.json             manifest: format, suite, thresholds, counts, suite hash, version
    data/<split>.parquet       one row per accepted instance (the instance record + fairness + preview)
    rejected/rejected.parquet  rejected instances, with who rejected them
    README.md                  the dataset card (roboview_data.benchmark.card)

Everything written is a pure function of the instance records: no timestamps, no machine paths,
so building twice gives the same bytes. `load_benchmark` reads it back into `TaskInstance`s; every
row must hash to its stored id.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import datasets
import pyarrow.parquet as pq

from roboview_data.variation.factors import FACTORS, factor_names, record_columns
from roboview_data.variation.instances import (
    TaskInstance,
    canonical_json,
    context_subspaces,
)

MANIFEST = "benchmark.json"
# 3: rows store `task` and `context_subspace`. 2: `context_subspace` is recovered by hashing (it is
# read still). 1: the `seed` column hashed instance_id (no longer read: other episode seeds).
FORMAT_VERSION = 3
READABLE_FORMATS = (2, 3)
# Columns that never travel into episode rows (docs/formats.md, "Episode records": everything but fairness and preview does).
NOT_IN_EPISODES = ("fairness", "preview")

_CAMERA = {"name": datasets.Value("string"), "pos": datasets.List(datasets.Value("float64")),
           "quat": datasets.List(datasets.Value("float64")), "fovy": datasets.Value("float64")}
_FAIR_CAMERA = {"camera": datasets.Value("string"), "object_visible": datasets.Value("float64"),
                "object_pixels": datasets.Value("int64"), "object_in_frame": datasets.Value("bool"),
                "box_visible": datasets.Value("float64"), "box_pixels": datasets.Value("int64"),
                "box_in_frame": datasets.Value("bool"), "delta_e_nominal": datasets.Value("float64"),
                "delta_e_table": datasets.Value("float64")}


class BenchmarkError(ValueError):
    """A folder that is not a readable RoboView benchmark (missing, failed, edited, other format)."""


def _feature(example: Any) -> Any:
    if isinstance(example, bool):
        return datasets.Value("bool")
    if isinstance(example, int):
        return datasets.Value("int64")
    if isinstance(example, float):
        return datasets.Value("float64")
    if isinstance(example, (list, tuple)):
        return datasets.List(_feature(example[0]))
    return datasets.Value("string")


def instance_features(task: str, rejected: bool = False) -> datasets.Features:
    """The instance record's schema for `task`: ids, every factor, each factor's extra columns."""
    cols = {name: datasets.Value("string") for name in ("instance_id", "task", "split", "factor", "value",
                                                         "context_id", "context_subspace", *factor_names(task))}
    examples = record_columns({name: FACTORS[name].baseline for name in factor_names(task)})
    cols |= {name: _feature(value) for name, value in examples.items()}
    cols |= {"cameras": datasets.List(_CAMERA), "seed": datasets.Value("int64"),
             "fairness": {"cameras": datasets.List(_FAIR_CAMERA), "passed": datasets.Value("bool"),
                          "reject_reason": datasets.Value("string"),
                          # stage 1b (optional): the VLM screen's yes / no / error and its analysis
                          "vlm_answer": datasets.Value("string"), "vlm_analysis": datasets.Value("string")},
             "preview": datasets.Image()}
    if rejected:
        cols["rejected_by"] = datasets.Value("string")
    return datasets.Features(cols)


def suite_hash(accepted: dict[str, list[dict]]) -> str:
    """SHA-256 over the accepted instance ids per split: ids hash every parameter of an instance."""
    payload = {split: sorted(r["instance_id"] for r in rows) for split, rows in accepted.items()}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


def write_split(rows: list[dict], path: Path, rejected: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    task = rows[0].get("task", "pick_place")
    ds = datasets.Dataset.from_list(rows, features=instance_features(task, rejected))
    ds.to_parquet(str(path))


def write_manifest(out: Path, manifest: dict) -> None:
    (out / MANIFEST).write_text(json.dumps({**manifest, "format": FORMAT_VERSION}, indent=2, sort_keys=True) + "\n")


def split_counts(records: list[dict], accepted: list[bool], rejected_by: list[str]) -> dict[str, dict]:
    counts: dict[str, Counter] = {}
    for r, ok, who in zip(records, accepted, rejected_by):
        c = counts.setdefault(r["split"], Counter())
        c["candidates"] += 1
        c["accepted"] += ok
        c["rejected_gate"] += (not ok) and who == "gate"
        c["rejected_review"] += (not ok) and who != "gate"
        c["accepted_over_gate"] += ok and not r["fairness"]["passed"]
    keys = ("candidates", "accepted", "rejected_gate", "rejected_review", "accepted_over_gate")
    return {split: {k: int(c[k]) for k in keys} for split, c in counts.items()}


def thresholds_dict(thresholds) -> dict:
    return asdict(thresholds)


# --- reading ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class BenchmarkItem:
    instance: TaskInstance
    record: dict  # the row's columns but fairness and preview: they travel into every episode row


@dataclass(frozen=True)
class Benchmark:
    path: Path
    version: str
    splits: dict[str, list[BenchmarkItem]]


def read_manifest(root: Path) -> dict:
    """The manifest of a finished, readable benchmark folder (else BenchmarkError saying what to do)."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise BenchmarkError(f"{root} holds no RoboView benchmark ({MANIFEST} missing); "
                             "build one with `python -m pipelines.build_benchmark`")
    manifest = json.loads(path.read_text())
    if manifest.get("format") not in READABLE_FORMATS:
        raise BenchmarkError(f"{root} has benchmark format {manifest.get('format')!r}; this version reads formats "
                             f"{', '.join(map(str, READABLE_FORMATS))} (episode seeds shared per context and repeat); "
                             "rebuild it with `python -m pipelines.build_benchmark`")
    if manifest.get("status") != "ok":
        raise BenchmarkError(f"{root} is a failed build; rebuild it")
    return manifest


def instance_from_record(record: dict) -> TaskInstance:
    """Rebuild the instance; its id must reproduce the stored one (else the row was edited)."""
    task = record.get("task") or "pick_place"
    factors = {name: record[name] for name in factor_names(task) if name in record}
    varied = tuple(record["factor"].split("|"))
    # Format 2 rows lack context_subspace: find the one that reproduces the id.
    subspaces = [record["context_subspace"]] if record.get("context_subspace") else context_subspaces(task)
    for subspace in subspaces:
        instance = TaskInstance(record["split"], varied, factors, subspace, task)
        if instance.instance_id == record["instance_id"]:
            return instance
    raise BenchmarkError(f"benchmark row {record['instance_id']} does not hash to its id: the split was "
                         "modified after it was built; rebuild it with pipelines.build_benchmark")


def available_splits(path: str | Path) -> list[str]:
    """The splits the benchmark folder at `path` holds, in its manifest's order."""
    root = Path(path)
    return [s for s in read_manifest(root)["splits"] if (root / "data" / f"{s}.parquet").is_file()]


def load_benchmark(path: str | Path, splits: list[str] | None = None) -> Benchmark:
    """The instances of `splits` (default: all) of the benchmark folder at `path`."""
    root = Path(path)
    manifest = read_manifest(root)
    available = available_splits(root)
    chosen = splits or available
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise BenchmarkError(f"unknown split(s) {unknown}; the benchmark at {root} has: {', '.join(available)}")
    out: dict[str, list[BenchmarkItem]] = {}
    for split in chosen:
        file = pq.ParquetFile(root / "data" / f"{split}.parquet")
        columns = [c for c in file.schema_arrow.names if c not in NOT_IN_EPISODES]
        out[split] = [BenchmarkItem(instance_from_record(row), row) for row in file.read(columns=columns).to_pylist()]
    return Benchmark(root, manifest["benchmark_version"], out)


def select_items(items: list[BenchmarkItem], contexts: int = 0, limit: int = 0) -> list[BenchmarkItem]:
    """The items an evaluation runs, in the split's fixed order: those of the first `contexts` task contexts
    (every value of each; 0 = all), then the first `limit` of those (0 = all). pipelines.evaluate and the
    lerobot-eval plugin both use it, so episode i means the same (instance, repeat) in both."""
    if contexts:
        first = set(list(dict.fromkeys(i.record["context_id"] for i in items))[:contexts])
        items = [i for i in items if i.record["context_id"] in first]
    return items[:limit] if limit else items
