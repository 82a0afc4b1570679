"""Episode results — written and read here, nowhere else.

A results folder holds `run.json` (what was run: benchmark version, policy and its options, repeats,
image size, results format), `episodes.jsonl` (the journal) and `episodes.parquet` (its table, with
the benchmark version, policy and results format in the parquet metadata). `EpisodeStore` writes a
folder crash-safely; `read_episodes` reads one parquet back, refusing other results formats.

Crash safety: a line-per-episode journal plus an atomically refreshed parquet.

Each finished episode is appended to `episodes.jsonl` and flushed to disk before anything else
happens, so a killed run loses at most the episodes still in flight. `episodes.parquet` is
rewritten from the journal (write to a temp file, then rename) every few seconds (less often once rewriting
takes long: never more than a tenth of the time) and at the end,
so readers always see a complete file. On resume the journal is read back (a torn last line is
dropped), deduplicated by (instance_id, repeat), and finished pairs are skipped.

An episode ended by infrastructure (`status` `infra_error`: a lost policy server, an endpoint outage, a dead
worker, a render failure) is not finished: it runs again, and its new row replaces the old one (the journal
appends it; the last line of a pair wins). `counted` keeps the rows every rate and test reads: those whose
status is not `infra_error` (rows written before the column existed have none, and count).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from roboview.core.folders import folder_problem
from roboview.eval.running import provenance
from roboview.eval.running.row import INFRA_ERROR, STATUS  # noqa: F401  (re-exported: readers of results)
from roboview.tasks.repetition import UNIT_COLUMN

JOURNAL = "episodes.jsonl"
PARQUET = "episodes.parquet"
RUN_FILE = "run.json"
# run.json keys added later, with the value every run written before them had (a resume of such a run matches).
RUN_DEFAULTS = {"control": "joint", "protocol": ""}
# run.json keys added later that follow from the others (`privileged` from the policy type): a run.json without
# them matches whatever this run records.
RUN_DERIVED = ("privileged", "torch_threads")
VERSION_KEY = "roboview_benchmark_version"  # parquet metadata key: the benchmark version a results file ran
FORMAT_KEY = b"roboview_results_format"
# 2: episode seeds from (context_id, repeat), shared by every value of a context (common random
# numbers); 1 (or no key): seeds hashed from instance_id. The two must never be mixed.
RESULTS_FORMAT = 2


def recorded_threads(folder: Path) -> int | None:
    """The intra-op threads each worker's torch policy ran the folder's episodes with: run.json's `torch_threads`,
    else (a folder written before run.json recorded them) the count every provenance entry records, when they all
    agree; None when neither says. A CPU policy's actions differ in their last bits with the count (torch splits
    its reductions by thread), enough to change an episode's steps: an episode is re-run with the same count."""
    run_file = Path(folder) / RUN_FILE
    run = json.loads(run_file.read_text()) if run_file.is_file() else {}
    if run.get("torch_threads"):
        return int(run["torch_threads"])
    counts = {(e.get("torch_threads") or {}).get("per_worker") for e in provenance.read(Path(folder))}
    return int(counts.pop()) if len(counts) == 1 and None not in counts else None


def more_repeats(existing, requested) -> bool:
    """Whether `requested` (run.json's n_repeats: split → repeats) only adds repeats to the same splits: the rows
    already written are then a prefix of the larger run, which resumes them and runs the new repeats (evaluating in
    rounds, one more repeat per call)."""
    return (
        isinstance(existing, dict)
        and isinstance(requested, dict)
        and existing.keys() == requested.keys()
        and all(requested[k] >= existing[k] for k in existing)
    )


class ResultsError(ValueError):
    """The output folder holds results that cannot be continued by this run."""


class EpisodeStore:
    def __init__(self, out: Path, run_info: dict, flush_every_s: float = 5.0) -> None:
        self.out = out
        self.run_info = {**run_info, "results_format": RESULTS_FORMAT}
        self.flush_every_s = flush_every_s
        self.rows: dict[tuple[str, int], dict] = {}
        self._last_flush = 0.0
        self._write_s = 0.0  # how long the last parquet rewrite took
        self._check_and_load()
        self._journal = (out / JOURNAL).open("a")

    def _check_and_load(self) -> None:
        out = self.out
        problem = folder_problem(
            out, "evaluation", RUN_FILE, "choose a new folder", label=f"results folder {out}", writing=True
        )
        if problem:
            raise ResultsError(problem)
        run_file = out / RUN_FILE
        if run_file.is_file():
            previous = json.loads(run_file.read_text())
            if previous.get("results_format", 1) != RESULTS_FORMAT:
                raise ResultsError(
                    f"results folder {out} holds results of format {previous.get('results_format', 1)} (episode seeds "
                    f"hashed from instance_id); this version writes format {RESULTS_FORMAT} (seeds shared per "
                    "context and repeat) and never mixes the two: choose a new folder"
                )
            diffs = [
                f"{k}: existing {previous.get(k, RUN_DEFAULTS.get(k))!r} vs requested {v!r}"
                for k, v in self.run_info.items()
                if previous.get(k, RUN_DEFAULTS.get(k)) != v
                and (k in previous or k not in RUN_DERIVED)
                and not (k == "n_repeats" and more_repeats(previous.get(k), v))
            ]
            if diffs:
                raise ResultsError(
                    f"results folder {out} holds results of a different run ({'; '.join(diffs)}); "
                    "rerun the same command to resume, or choose a new folder"
                )
        out.mkdir(parents=True, exist_ok=True)
        run_file.write_text(json.dumps(self.run_info, indent=2, sort_keys=True))
        journal = out / JOURNAL
        if journal.is_file():
            self.rows = {(row["instance_id"], row["repeat"]): row for row in read_journal(out)}
            # Rewrite the journal without torn lines so appends start on a clean line.
            tmp = journal.with_suffix(".tmp")
            tmp.write_text("".join(json.dumps(r) + "\n" for r in self.rows.values()))
            tmp.replace(journal)

    def add_many(self, rows: list[dict]) -> int:
        """Journal several rows with one flush to disk (merging folders); returns how many were new."""
        new = [r for r in rows if not self.done((r["instance_id"], r["repeat"]))]
        for row in new:
            self.rows[(row["instance_id"], row["repeat"])] = row
            self._journal.write(json.dumps(row) + "\n")
        self._journal.flush()
        os.fsync(self._journal.fileno())
        return len(new)

    def saved(self) -> int:
        """Episodes in the journal on disk now, its buffer flushed first: what a rerun resumes from. A Ctrl-C can land
        inside `add`, between keeping a row and writing it, so `rows` may hold one more than the disk."""
        self._journal.flush()
        os.fsync(self._journal.fileno())
        return len(read_journal(self.out))

    def done(self, key: tuple[str, int]) -> bool:
        """The pair has a row that counts (one ended by infrastructure is run again)."""
        return key in self.rows and is_counted(self.rows[key])

    def infra_error(self, key: tuple[str, int]) -> bool:
        """The pair's row says infrastructure ended it."""
        return key in self.rows and not is_counted(self.rows[key])

    def add(self, row: dict) -> None:
        key = (row["instance_id"], row["repeat"])
        if self.done(key):
            return  # a retried episode that had in fact finished: same seed, same row
        self.rows[key] = row
        self._journal.write(json.dumps(row) + "\n")
        self._journal.flush()
        os.fsync(self._journal.fileno())
        # The parquet is rewritten whole (≈ 2 s per 100,000 rows): at most every flush_every_s, and never more
        # than a tenth of the time, so large runs are not slowed by their own table.
        if time.monotonic() - self._last_flush > max(self.flush_every_s, 10 * self._write_s):
            self.write_parquet()

    def write_parquet(self) -> Path:
        start = time.monotonic()
        rows = sorted(self.rows.values(), key=lambda r: (r["split"], r["instance_id"], r["repeat"]))
        # Every row gets every column (a policy's own columns may be missing from some rows, e.g.
        # those journalled before a resume); pyarrow would take the first row's keys only.
        columns = list(dict.fromkeys(k for row in rows for k in row))
        table = (
            pa.Table.from_pylist([{k: row.get(k) for k in columns} for row in rows]) if rows else pa.table({})
        )
        meta = {
            VERSION_KEY.encode(): self.run_info["benchmark_version"].encode(),
            b"roboview_policy": self.run_info["policy"].encode(),
            FORMAT_KEY: str(RESULTS_FORMAT).encode(),
        }
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
        path = self.out / PARQUET
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        tmp.replace(path)
        self._last_flush = time.monotonic()
        self._write_s = self._last_flush - start
        return path

    def close(self) -> None:
        self.write_parquet()
        self._journal.close()


def is_counted(row: dict) -> bool:
    """Whether an episode row counts in rates and tests: its status is not `infra_error` (none: it counts)."""
    return row.get(STATUS) != INFRA_ERROR


def infra_mask(episodes: pd.DataFrame) -> pd.Series:
    """True for the rows of an episodes table that infrastructure ended (a table without `status`: none)."""
    if STATUS not in episodes:
        return pd.Series(False, index=episodes.index)
    return (episodes[STATUS] == INFRA_ERROR).fillna(False).astype(bool)


def copies_mask(episodes: pd.DataFrame) -> pd.Series:
    """True for the repeats (beyond repeat 0) that copy repeat 0's episode: rows of a world whose repeats must advance
    a context factor (LIBERO's init state) recorded without `episode_unit`, i.e. by the seed-only design, where every
    repeat of an instance started from the same init state (roboview.tasks.repetition)."""
    from roboview.tasks import load_task

    mask = pd.Series(False, index=episodes.index)
    if "task" not in episodes or "repeat" not in episodes:
        return mask
    advancing = [t for t in episodes["task"].dropna().unique() if load_task(str(t)).repeat_factor]
    unrecorded = episodes[UNIT_COLUMN].isna() if UNIT_COLUMN in episodes else True
    return mask | (episodes["task"].isin(advancing) & unrecorded & (episodes["repeat"] > 0))


def counted(episodes: pd.DataFrame) -> pd.DataFrame:
    """The rows every rate and test reads: all but those infrastructure ended, and the independent unit only (a
    seed-only repeat of a LIBERO episode is a copy of repeat 0: `copies_mask`)."""
    mask = infra_mask(episodes) | copies_mask(episodes)
    return episodes if not mask.any() else episodes[~mask]


def read_version(path: str | Path) -> str | None:
    """The results file's benchmark version (parquet metadata); None when it records none."""
    raw = (pq.read_schema(path).metadata or {}).get(VERSION_KEY.encode())
    return None if raw is None else raw.decode()


def read_episodes(path: str | Path) -> pd.DataFrame:
    """The episode rows of one results parquet; other results formats raise ResultsError."""
    check_format(path)
    return pd.read_parquet(path)


def check_format(path: str | Path) -> None:
    """ResultsError unless the results parquet at `path` is of this version's results format (its footer only)."""
    fmt = (pq.read_schema(path).metadata or {}).get(FORMAT_KEY)
    if fmt != str(RESULTS_FORMAT).encode():
        found = "none (format 1)" if fmt is None else fmt.decode()
        raise ResultsError(
            f"{path} was written with results format {found}, whose episode seeds hashed instance_id; "
            f"this version reads format {RESULTS_FORMAT} only (seeds shared per context and repeat, the "
            "pairing its statistics rely on). Re-run roboview.pipelines.evaluate into a new output folder"
        )


def shard_of(instance_id: str, n: int) -> int:
    """The shard (of n) an instance belongs to: SHA-256 of its id modulo n, the same on every machine."""
    return int.from_bytes(hashlib.sha256(instance_id.encode()).digest()[:8], "big") % n


def read_journal(folder: Path) -> list[dict]:
    """The rows of a results folder's journal, one per (instance_id, repeat); a line torn by a kill mid-write is
    dropped (that episode reruns)."""
    rows: dict[tuple[str, int], dict] = {}
    path = Path(folder) / JOURNAL
    for line in path.read_text().splitlines() if path.is_file() else []:
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        rows[(row["instance_id"], row["repeat"])] = row
    return list(rows.values())


def merge_folders(
    folders: list[Path], out: Path, partial: bool = False
) -> tuple[EpisodeStore, dict[str, int]]:
    """Join the results folders of one sharded run (`--eval.shard=i/N`) into `out`.

    Refused, before anything is written: folders of different runs (benchmark version, policy, its options,
    repeats, image size...), shards of different N, a shard given twice, missing shards (unless `partial`), and
    any episode found in two folders. Videos are copied; provenance entries are kept, each with its shard.
    Returns the store (closed) and episodes per input folder.
    """
    if len(folders) < 2:
        raise ResultsError(f"merging needs two results folders or more, got {len(folders)}")
    infos = [_run_info(folder) for folder in folders]
    base = _common_run(folders, infos)
    shards = [info.get("shard") for info in infos]
    n = _shard_count(folders, shards, partial)
    per_folder = _disjoint_rows(folders)
    if any(Path(out).resolve() == Path(f).resolve() for f in folders):
        raise ResultsError(f"--output_dir={out} is one of the folders being merged; choose a new folder")
    store = EpisodeStore(Path(out), {**base, "merged_shards": f"{len(shards)}/{n}"})
    entries = []
    for folder, shard in zip(folders, shards):
        _copy_videos(per_folder[str(folder)], Path(folder), Path(out))
        store.add_many(per_folder[str(folder)])
        entries += [{**entry, "shard": shard} for entry in provenance.read(Path(folder))]
    provenance.write(Path(out), entries)
    store.close()
    return store, {k: len(v) for k, v in per_folder.items()}


def _run_info(folder: Path) -> dict:
    """A results folder's run.json; ResultsError when it holds none."""
    run_file = Path(folder) / RUN_FILE
    if not run_file.is_file():
        raise ResultsError(f"{folder} holds no RoboView evaluation ({RUN_FILE} missing)")
    return json.loads(run_file.read_text())


def _common_run(folders: list[Path], infos: list[dict]) -> dict:
    """The run.json the shards share, less its `shard`; ResultsError naming what differs when they do not. Shards
    on machines of other sizes may have run with other inference threads: the merge keeps the count only where
    every shard ran with it (each shard's own stays in its provenance entries)."""
    own = {"shard", "torch_threads"}
    base = {k: v for k, v in infos[0].items() if k not in own}
    for folder, info in zip(folders[1:], infos[1:]):
        diffs = [
            f"{k}: {base.get(k)!r} in {folders[0]} vs {info.get(k)!r}"
            for k in sorted(set(base) | set(info) - own)
            if base.get(k) != info.get(k)
        ]
        if diffs:
            raise ResultsError(f"{folder} is not a shard of the same run as {folders[0]}: {'; '.join(diffs)}")
    threads = {info.get("torch_threads") for info in infos}
    return base | ({"torch_threads": threads.pop()} if len(threads) == 1 and None not in threads else {})


def _shard_count(folders: list[Path], shards: list[str | None], partial: bool) -> int:
    """N of the shards "i/N" given; ResultsError for an unsharded folder, shards of different N, a shard given
    twice, or (unless `partial`) a shard missing."""
    if any(s is None for s in shards):
        raise ResultsError(
            "only shards of one run merge (folders written with --eval.shard=i/N); "
            f"{folders[shards.index(None)]} was not sharded"
        )
    counts = {int(s.split("/")[1]) for s in shards}
    if len(counts) > 1:
        raise ResultsError(f"the folders are shards of different counts: {', '.join(sorted(set(shards)))}")
    n = counts.pop()
    seen: dict[str, Path] = {}
    for folder, shard in zip(folders, shards):
        if shard in seen:
            raise ResultsError(f"shard {shard} is given twice: {seen[shard]} and {folder}")
        seen[shard] = folder
    missing = [f"{i}/{n}" for i in range(n) if f"{i}/{n}" not in seen]
    if missing and not partial:
        raise ResultsError(
            f"shard(s) {', '.join(missing)} missing: give every shard of the run, or pass "
            "--partial=true to merge what there is"
        )
    return n


def _disjoint_rows(folders: list[Path]) -> dict[str, list[dict]]:
    """folder → its journal's rows; ResultsError when an episode (instance, repeat) is in two folders."""
    owner: dict[tuple[str, int], Path] = {}
    per_folder: dict[str, list[dict]] = {}
    for folder in folders:
        rows = read_journal(folder)
        for row in rows:
            key = (row["instance_id"], row["repeat"])
            if key in owner:
                raise ResultsError(
                    f"episode {key[0]} repeat {key[1]} is in both {owner[key]} and {folder}: "
                    "these folders overlap; merge shards of one run only"
                )
            owner[key] = folder
        per_folder[str(folder)] = rows
    return per_folder


def _copy_videos(rows: list[dict], folder: Path, out: Path) -> None:
    """Copy the videos the rows name (relative paths) from their results folder into `out`, once each."""
    for row in rows:
        for rel in (row.get("video") or "").split(","):
            if rel and (folder / rel).is_file() and not (out / rel).is_file():
                (out / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(folder / rel, out / rel)


def is_privileged_run(run: dict) -> bool:
    """Whether a results folder's run.json records a privileged policy (one that reads the simulator state).
    run.json written before the `privileged` key: the recorded type's `PolicyConfig.privileged`."""
    if "privileged" in run:
        return bool(run["privileged"])
    from roboview.policies.base import PolicyConfig
    from roboview.policies.types import load_policy_types

    kind = str(run.get("policy") or "")
    return kind in load_policy_types() and PolicyConfig.get_choice_class(kind).privileged
