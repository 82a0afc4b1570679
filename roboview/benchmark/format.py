"""The frozen benchmark folder — written and read here, nowhere else.

A benchmark is a Hugging Face dataset folder:

    benchmark.json             manifest: format, suite, thresholds, counts, suite hash, content hashes,
                               the simulation stack that built it, version
    checksums.json             per table: a SHA-256 per column and a short one per row
    data/<split>.parquet       one row per accepted instance (the instance record + fairness + preview)
    rejected/rejected.parquet  rejected instances, with who rejected them
    conformance/               the reference sample roboview.pipelines.verify re-renders (roboview.benchmark.conformance)
    README.md                  the dataset card (roboview.benchmark.card)

Everything written is a pure function of the instance records and the stack that rendered them: no
timestamps, no machine paths, so building twice on one stack gives the same bytes.

Identity: every cell of every table is hashed (`content_checksums`); a table's hash covers its column and row
hashes, and the benchmark version derives from every table's hash and the conformance reference. Loading a
split recomputes its hashes and refuses a table edited after the build, naming the row and the column; each
row must also rebuild into an instance whose id, value, context and seed are the stored ones.

Baseline labels: from format 5 a factor whose baseline is its world's own look is stored under the world's label
(LIBERO's and Meta-World's color `original`; red there is a red re-skin). A format-4 benchmark, built when that
baseline was stored as the registered value (`red`), reads as its build meant it: in such a task a row's registered
baseline becomes the label (`labelled`), under the id it was published with.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow.parquet as pq

from roboview.benchmark.protocols import Protocol, declared
from roboview.core.files import files_sha256
from roboview.core.folders import folder_problem
from roboview.tasks.repetition import SEED_ONLY, Repetition, repetition_of
from roboview.variation.factors import DEFAULT_TASK, FACTORS, baseline_of, factor_names, record_columns
from roboview.variation.instances import TaskInstance, canonical_json

if TYPE_CHECKING:
    import datasets

MANIFEST = "benchmark.json"
# benchmark.json's `status` of a build that passed its gate (a failed one says "failed_gate").
BUILT, FAILED_GATE = "ok", "failed_gate"
CHECKSUMS = "checksums.json"
# The conformance reference (roboview.benchmark.conformance writes and checks it).
CONFORMANCE = "conformance"
REFERENCE = "reference.json"
# 5: a factor whose baseline is its world's own look is stored under the world's label (LIBERO's and Meta-World's
# color `original`), so their `red` is a red re-skin. 4: content hashes over every cell, the simulation stack and the
# conformance reference; read with the registered baseline it stored there (`red`) as the label (`labelled`).
# 3: rows store `task` and `context_subspace`. 2: `context_subspace` recovered by hashing. 1: the `seed` column
# hashed instance_id. Formats before 4 carry no content hashes, so an edit would pass: they are not read.
FORMAT_VERSION = 5
READABLE_FORMATS = (4, 5)
LABELLED_FORMAT = 5
# Columns that never travel into episode rows (docs/formats.md, "Episode records": everything but fairness and preview does).
NOT_IN_EPISODES = ("fairness", "preview")
# The episode column carrying the gate's verdict of the instance, in a benchmark that keeps an external benchmark's
# variants whatever the gate says (its manifest's `ungated_splits`).
GATE_COLUMN = "gate_passed"


class BenchmarkError(ValueError):
    """A folder that is not a readable RoboView benchmark (missing, failed, edited, other format)."""


def _feature(example: Any) -> Any:
    import datasets

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
    import datasets  # here, not at the top: readers of a benchmark (every evaluation worker) need none of it

    camera = {
        "name": datasets.Value("string"),
        "pos": datasets.List(datasets.Value("float64")),
        "quat": datasets.List(datasets.Value("float64")),
        "fovy": datasets.Value("float64"),
    }
    fair_camera = {
        "camera": datasets.Value("string"),
        "object_visible": datasets.Value("float64"),
        "object_pixels": datasets.Value("int64"),
        "object_in_frame": datasets.Value("bool"),
        "box_visible": datasets.Value("float64"),
        "box_pixels": datasets.Value("int64"),
        "box_in_frame": datasets.Value("bool"),
        "delta_e_nominal": datasets.Value("float64"),
        "delta_e_table": datasets.Value("float64"),
    }
    cols = {
        name: datasets.Value("string")
        for name in (
            "instance_id",
            "task",
            "split",
            "factor",
            "value",
            "context_id",
            "context_subspace",
            *factor_names(task),
        )
    }
    # The registered baselines: a value of every factor whose extra columns have the types every value's share (a
    # world's baseline label, `original`, fills the same columns with an empty hex and nulls).
    examples = record_columns({name: FACTORS[name].baseline for name in factor_names(task)})
    cols |= {name: _feature(value) for name, value in examples.items()}
    cols |= {
        "cameras": datasets.List(camera),
        "seed": datasets.Value("int64"),
        "fairness": {
            "cameras": datasets.List(fair_camera),
            "passed": datasets.Value("bool"),
            "reject_reason": datasets.Value("string"),
            # stage 1b (optional): the VLM screen's yes / no / error and its analysis
            "vlm_answer": datasets.Value("string"),
            "vlm_analysis": datasets.Value("string"),
        },
        "preview": datasets.Image(),
    }
    if rejected:
        cols["rejected_by"] = datasets.Value("string")
    return datasets.Features(cols)


def suite_hash(accepted: dict[str, list[dict]]) -> str:
    """SHA-256 over the accepted instance ids per split: ids hash every parameter of an instance."""
    payload = {split: sorted(r["instance_id"] for r in rows) for split, rows in accepted.items()}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


def write_split(rows: list[dict], path: Path, rejected: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    import datasets

    task = rows[0].get("task", DEFAULT_TASK)
    ds = datasets.Dataset.from_list(rows, features=instance_features(task, rejected))
    ds.to_parquet(str(path))


# --- content identity ---------------------------------------------------------------------------------


def _plain(value: Any) -> Any:
    """A cell as JSON values: bytes (a preview's PNG) by their SHA-256."""
    if isinstance(value, bytes):
        return {"sha256": hashlib.sha256(value).hexdigest()}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _cell_digest(value: Any) -> bytes:
    return hashlib.sha256(json.dumps(_plain(value), sort_keys=True, separators=(",", ":")).encode()).digest()


def content_checksums(rows: list[dict], columns: list[str]) -> dict:
    """Per column a SHA-256 over its cells in row order, per row a short SHA-256 over its cells, and the
    table's SHA-256 over both (floats hashed exactly, as stored)."""
    per_column = {c: hashlib.sha256() for c in columns}
    per_row = []
    for row in rows:
        digest = hashlib.sha256()
        for c in columns:
            cell = _cell_digest(row[c])
            per_column[c].update(cell)
            digest.update(c.encode() + b"\0" + cell)
        per_row.append(digest.hexdigest()[:16])
    checksums = {"columns": {c: h.hexdigest() for c, h in per_column.items()}, "rows": per_row}
    return {"sha256": hashlib.sha256(canonical_json(checksums).encode()).hexdigest(), **checksums}


def read_rows(path: Path) -> list[dict]:
    """A benchmark table's rows, every column, as stored."""
    return pq.read_table(path).to_pylist()


def table_checksums(path: Path) -> dict:
    """`content_checksums` of a parquet table as stored (what loading recomputes)."""
    return _read_checked(path)[1]


def _read_checked(path: Path) -> tuple[list[dict], dict]:
    """A table's rows and their `content_checksums`, from one read."""
    table = pq.read_table(path)
    rows = table.to_pylist()
    return rows, content_checksums(rows, table.column_names)


def table_name(root: Path, path: Path) -> str:
    """A table's name in checksums.json: its path under the benchmark folder without .parquet."""
    return path.relative_to(root).with_suffix("").as_posix()


def write_checksums(root: Path) -> dict[str, str]:
    """checksums.json for every table under root/data and root/rejected; returns table → SHA-256."""
    root = Path(root)
    tables = sorted([*root.glob("data/*.parquet"), *root.glob("rejected/*.parquet")])
    sums = {table_name(root, path): table_checksums(path) for path in tables}
    (root / CHECKSUMS).write_text(json.dumps(sums, indent=1, sort_keys=True) + "\n")
    return {name: entry["sha256"] for name, entry in sums.items()}


def reference_hash(root: Path) -> str | None:
    """SHA-256 over the conformance reference's files (names and bytes, sorted); None when the folder has none."""
    folder = Path(root) / CONFORMANCE
    if not (folder / REFERENCE).is_file():
        return None
    return files_sha256(folder, sorted(folder.iterdir()))


def benchmark_version(
    preset: str, content: dict[str, str], conformance: str | None, protocols: dict | None = None
) -> str:
    """`<preset>-<12 hex>`: SHA-256 over every table's content hash, the conformance reference's and the declared
    protocols (a manifest written before protocols were declared hashes without them: its version stands)."""
    hashed: dict[str, Any] = {"content": content, "conformance": conformance}
    if protocols:
        hashed["protocols"] = protocols
    digest = hashlib.sha256(canonical_json(hashed).encode()).hexdigest()
    return f"{preset}-{digest[:12]}"


def _edited(root: Path, table: str, found: dict, stored: dict | None) -> str:
    """What no longer matches in `table`: columns added, missing or changed, and the rows they changed in."""
    where = f"benchmark table {table!r} in {root}"
    if stored is None:
        return f"{where} is not in {CHECKSUMS}"
    added = sorted(set(found["columns"]) - set(stored["columns"]))
    missing = sorted(set(stored["columns"]) - set(found["columns"]))
    if added or missing:
        return f"{where} has column(s) {added} added and {missing} removed since it was built"
    if len(found["rows"]) != len(stored["rows"]):
        return f"{where} holds {len(found['rows'])} rows; it was built with {len(stored['rows'])}"
    columns = [c for c in stored["columns"] if found["columns"][c] != stored["columns"][c]]
    rows = [i for i, (a, b) in enumerate(zip(found["rows"], stored["rows"])) if a != b]
    if not columns and not rows:
        return f"{where}: {CHECKSUMS} itself no longer matches the manifest"
    return (
        f"{where} was edited after it was built: column(s) {', '.join(map(repr, columns))} of row(s) "
        f"{', '.join(map(str, rows[:10]))}{' …' if len(rows) > 10 else ''} no longer match their checksums"
    )


def verify_table(root: Path, path: Path, manifest: dict) -> list[dict]:
    """The rows of a benchmark table, after checking every cell against the build's checksums."""
    root = Path(root)
    name = table_name(root, path)
    rows, found = _read_checked(path)
    if found["sha256"] != manifest.get("content", {}).get(name):
        sums_path = root / CHECKSUMS
        stored = json.loads(sums_path.read_text()).get(name) if sums_path.is_file() else None
        raise BenchmarkError(
            _edited(root, name, found, stored) + "; rebuild it with `roboview-build-benchmark` "
            "or download the published benchmark again"
        )
    return rows


def write_manifest(out: Path, manifest: dict) -> None:
    (out / MANIFEST).write_text(
        json.dumps({**manifest, "format": FORMAT_VERSION}, indent=2, sort_keys=True) + "\n"
    )


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


# --- reading ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class BenchmarkItem:
    instance: TaskInstance
    record: dict  # the row's columns but fairness and preview: they travel into every episode row
    # What repeat r of the instance runs (roboview.tasks.repetition): the seed alone, or LIBERO's next init state.
    repetition: Repetition = SEED_ONLY
    # The record as its build wrote it, where this version reads it otherwise (a format-4 row whose world now labels
    # its baseline: `red` there read as `original`; `labelled`); None: `record` is as written.
    as_built: dict | None = None

    def episode(self, repeat: int) -> TaskInstance:
        """The instance the env is reset with for repeat `repeat` (the row is recorded under `record`)."""
        return self.repetition.instance(self.instance, repeat)


@dataclass(frozen=True)
class Benchmark:
    path: Path
    version: str
    splits: dict[str, list[BenchmarkItem]]
    # The protocols it can be evaluated under (roboview.benchmark.protocols), over all its splits.
    protocols: dict[str, Protocol] = field(default_factory=dict)
    # benchmark.json as read and checked once (its stack, suite, content): checks that need it take it from here.
    manifest: dict = field(default_factory=dict)


def read_manifest(root: Path) -> dict:
    """The manifest of a finished, readable benchmark folder (else BenchmarkError saying what to do)."""
    problem = folder_problem(Path(root), "benchmark", MANIFEST, "build one with `roboview-build-benchmark`")
    if problem:
        raise BenchmarkError(problem)
    path = Path(root) / MANIFEST
    manifest = json.loads(path.read_text())
    if manifest.get("format") not in READABLE_FORMATS:
        raise BenchmarkError(
            f"{root} has benchmark format {manifest.get('format')!r}; this version reads formats "
            f"{', '.join(map(str, READABLE_FORMATS))} (episode seeds shared per context and repeat); "
            "rebuild it with `roboview-build-benchmark`"
        )
    if manifest.get("status") != BUILT:
        raise BenchmarkError(f"{root} is a failed build; rebuild it")
    expected = benchmark_version(
        manifest["suite"]["preset"],
        manifest.get("content", {}),
        reference_hash(root),
        manifest.get("protocols"),
    )
    if manifest.get("benchmark_version") != expected:
        raise BenchmarkError(
            f"{root}/{MANIFEST} names version {manifest.get('benchmark_version')!r} but its content "
            f"hashes, conformance reference and protocols give {expected!r}: the manifest or the conformance "
            "folder was edited after the build; rebuild it or download it again"
        )
    return manifest


# Columns an instance derives from its parameters; a row must carry exactly these values.
DERIVED = ("value", "context_id", "seed", "task")


def benchmark_format(root: Path) -> int | None:
    """The format benchmark.json at `root` declares (None: none)."""
    return json.loads((Path(root) / MANIFEST).read_text()).get("format")


def labelled(record: dict) -> dict:
    """A row of a benchmark written before worlds labelled their baselines (format 4) as this version reads it: where
    the row's task's world labels a factor's baseline (`baseline_of`: LIBERO's and Meta-World's color `original`), the
    registered baseline the row stored there (`red`, which then meant the object's own look) becomes the label, in the
    factor's column, in `value` and in the factor's record columns (`color_hex`…). Any other row: itself."""
    task = record.get("task") or DEFAULT_TASK
    changed = {
        name: baseline_of(name, task)
        for name in factor_names(task)
        if baseline_of(name, task) != FACTORS[name].baseline and record.get(name) == FACTORS[name].baseline
    }
    if not changed:
        return record
    out = {**record, **changed}
    if "value" in record:
        out["value"] = "|".join(out[name] for name in record["factor"].split("|"))
    extra = record_columns(changed)
    return out | {name: value for name, value in extra.items() if name in record}


def instance_from_record(record: dict, fmt: int | None = FORMAT_VERSION) -> TaskInstance:
    """Rebuild the instance; its id, value, context and seed must reproduce the stored ones (else the row was
    edited: a `value` that names another color, a `context_id` or `seed` that leaves its context's common random
    numbers). `fmt`: the benchmark's format; a format-4 row whose world labels a baseline it stored as the registered
    value is rebuilt at the label (`labelled`), under the id it was published with."""
    task = record.get("task") or DEFAULT_TASK
    factors = {name: record[name] for name in factor_names(task) if name in record}
    try:
        instance = TaskInstance(
            record["split"], tuple(record["factor"].split("|")), factors, record["context_subspace"], task
        )
    except (KeyError, ValueError) as exc:
        raise BenchmarkError(
            f"benchmark row {record.get('instance_id')} is not a valid instance ({exc}); "
            "rebuild the benchmark with roboview.pipelines.build_benchmark"
        ) from None
    if instance.instance_id != record["instance_id"]:
        raise BenchmarkError(
            f"benchmark row {record['instance_id']} does not hash to its id: its factor columns "
            "were modified after it was built; rebuild it with roboview.pipelines.build_benchmark"
        )
    for column in DERIVED:
        if column in record and record[column] != getattr(instance, column):
            raise BenchmarkError(
                f"benchmark row {record['instance_id']}: column {column!r} holds "
                f"{record[column]!r} but the instance's parameters give {getattr(instance, column)!r}; "
                "the row was edited after it was built: rebuild it with roboview.pipelines.build_benchmark"
            )
    if fmt is not None and fmt < LABELLED_FORMAT and (read := labelled(record)) is not record:
        meant = TaskInstance(
            instance.split,
            instance.varied,
            {name: read[name] for name, _ in instance.factors},
            instance.context_subspace,
            instance.task,
        )
        object.__setattr__(meant, "instance_id", record["instance_id"])  # the id it was published with
        return meant
    return instance


def available_splits(path: str | Path, manifest: dict | None = None) -> list[str]:
    """The splits the benchmark folder at `path` holds, in its manifest's order (`manifest`: already read)."""
    root = Path(path)
    return [
        s for s in (manifest or read_manifest(root))["splits"] if (root / "data" / f"{s}.parquet").is_file()
    ]


def load_benchmark(path: str | Path, splits: list[str] | None = None) -> Benchmark:
    """The instances of `splits` (default: all) of the benchmark folder at `path`."""
    root = Path(path)
    manifest = read_manifest(root)
    available = available_splits(root, manifest)
    chosen = splits or available
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise BenchmarkError(
            f"unknown split(s) {unknown}; the benchmark at {root} has: {', '.join(available)}"
        )
    out: dict[str, list[BenchmarkItem]] = {}
    rules: dict[str, Repetition] = {}
    fmt = manifest.get("format")
    kept_over_gate = bool(manifest.get("ungated_splits"))
    for split in chosen:
        rows = verify_table(root, root / "data" / f"{split}.parquet", manifest)
        out[split] = []
        for row in rows:
            instance = instance_from_record(row, fmt)
            if instance.task not in rules:
                rules[instance.task] = repetition_of(instance.task, manifest.get("suite"))
            written = {k: v for k, v in row.items() if k not in NOT_IN_EPISODES}
            if (
                kept_over_gate
            ):  # an external benchmark's set kept whatever the gate said: its verdict travels along
                written[GATE_COLUMN] = bool(row["fairness"]["passed"])
            record = labelled(written) if fmt < LABELLED_FORMAT else written
            built = written if record is not written else None
            out[split].append(BenchmarkItem(instance, record, rules[instance.task], built))
    return Benchmark(root, manifest["benchmark_version"], out, declared(manifest, available), manifest)


def select_items(items: list[BenchmarkItem], contexts: int = 0, limit: int = 0) -> list[BenchmarkItem]:
    """The items an evaluation runs, in the split's fixed order: those of the first `contexts` task contexts
    (every value of each; 0 = all), then the first `limit` of those (0 = all). roboview.pipelines.evaluate and the
    lerobot-eval plugin both use it, so episode i means the same (instance, repeat) in both."""
    if contexts:
        first = set(list(dict.fromkeys(i.record["context_id"] for i in items))[:contexts])
        items = [i for i in items if i.record["context_id"] in first]
    return items[:limit] if limit else items
