"""Episode results — written and read here, nowhere else.

A results folder holds `run.json` (what was run: benchmark version, policy and its options, repeats,
image size, results format), `episodes.jsonl` (the journal) and `episodes.parquet` (its table, with
the benchmark version, policy and results format in the parquet metadata). `EpisodeStore` writes a
folder crash-safely; `read_episodes` reads one parquet back, refusing other results formats.

Crash safety: a line-per-episode journal plus an atomically refreshed parquet.

Each finished episode is appended to `episodes.jsonl` and flushed to disk before anything else
happens, so a killed run loses at most the episodes still in flight. `episodes.parquet` is
rewritten from the journal (write to a temp file, then rename) every few seconds and at the end,
so readers always see a complete file. On resume the journal is read back (a torn last line is
dropped), deduplicated by (instance_id, repeat), and finished pairs are skipped.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

JOURNAL = "episodes.jsonl"
PARQUET = "episodes.parquet"
RUN_FILE = "run.json"
VERSION_KEY = b"roboview_benchmark_version"
FORMAT_KEY = b"roboview_results_format"
# 2: episode seeds from (context_id, repeat), shared by every value of a context (common random
# numbers); 1 (or no key): seeds hashed from instance_id. The two must never be mixed.
RESULTS_FORMAT = 2


class ResultsError(ValueError):
    """The output folder holds results that cannot be continued by this run."""


class EpisodeStore:
    def __init__(self, out: Path, run_info: dict, flush_every_s: float = 5.0) -> None:
        self.out = out
        self.run_info = {**run_info, "results_format": RESULTS_FORMAT}
        self.flush_every_s = flush_every_s
        self.rows: dict[tuple[str, int], dict] = {}
        self._last_flush = 0.0
        self._check_and_load()
        self._journal = (out / JOURNAL).open("a")

    def _check_and_load(self) -> None:
        out = self.out
        if out.exists() and not out.is_dir():
            raise ResultsError(f"results folder {out} is a file; give a folder")
        run_file = out / RUN_FILE
        if out.is_dir() and any(out.iterdir()) and not run_file.is_file():
            raise ResultsError(f"results folder {out} is not empty and holds no RoboView evaluation "
                               f"({RUN_FILE} missing); choose a new folder")
        if run_file.is_file():
            previous = json.loads(run_file.read_text())
            if previous.get("results_format", 1) != RESULTS_FORMAT:
                raise ResultsError(
                    f"results folder {out} holds results of format {previous.get('results_format', 1)} (episode seeds "
                    f"hashed from instance_id); this version writes format {RESULTS_FORMAT} (seeds shared per "
                    "context and repeat) and never mixes the two: choose a new folder")
            diffs = [f"{k}: existing {previous.get(k)!r} vs requested {v!r}"
                     for k, v in self.run_info.items() if previous.get(k) != v]
            if diffs:
                raise ResultsError(f"results folder {out} holds results of a different run ({'; '.join(diffs)}); "
                                   "rerun the same command to resume, or choose a new folder")
        out.mkdir(parents=True, exist_ok=True)
        run_file.write_text(json.dumps(self.run_info, indent=2, sort_keys=True))
        journal = out / JOURNAL
        if journal.is_file():
            for line in journal.read_text().splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line torn by a kill mid-write; that episode reruns
                self.rows[(row["instance_id"], row["repeat"])] = row
            # Rewrite the journal without torn lines so appends start on a clean line.
            tmp = journal.with_suffix(".tmp")
            tmp.write_text("".join(json.dumps(r) + "\n" for r in self.rows.values()))
            tmp.replace(journal)

    def done(self, key: tuple[str, int]) -> bool:
        return key in self.rows

    def add(self, row: dict) -> None:
        key = (row["instance_id"], row["repeat"])
        if key in self.rows:
            return  # a retried episode that had in fact finished: same seed, same row
        self.rows[key] = row
        self._journal.write(json.dumps(row) + "\n")
        self._journal.flush()
        os.fsync(self._journal.fileno())
        if time.monotonic() - self._last_flush > self.flush_every_s:
            self.write_parquet()

    def write_parquet(self) -> Path:
        rows = sorted(self.rows.values(), key=lambda r: (r["split"], r["instance_id"], r["repeat"]))
        # Every row gets every column (a policy's own columns may be missing from some rows, e.g.
        # those journalled before a resume); pyarrow would take the first row's keys only.
        columns = list(dict.fromkeys(k for row in rows for k in row))
        table = pa.Table.from_pylist([{k: row.get(k) for k in columns} for row in rows]) if rows else pa.table({})
        meta = {VERSION_KEY: self.run_info["benchmark_version"].encode(),
                b"roboview_policy": self.run_info["policy"].encode(), FORMAT_KEY: str(RESULTS_FORMAT).encode()}
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
        path = self.out / PARQUET
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        tmp.replace(path)
        self._last_flush = time.monotonic()
        return path

    def close(self) -> None:
        self.write_parquet()
        self._journal.close()


def read_version(path: str | Path) -> str | None:
    """The results file's benchmark version (parquet metadata); None when it records none."""
    raw = (pq.read_schema(path).metadata or {}).get(VERSION_KEY)
    return None if raw is None else raw.decode()


def read_episodes(path: str | Path) -> pd.DataFrame:
    """The episode rows of one results parquet; other results formats raise ResultsError."""
    fmt = (pq.read_schema(path).metadata or {}).get(FORMAT_KEY)
    if fmt != str(RESULTS_FORMAT).encode():
        found = "none (format 1)" if fmt is None else fmt.decode()
        raise ResultsError(
            f"{path} was written with results format {found}, whose episode seeds hashed instance_id; "
            f"this version reads format {RESULTS_FORMAT} only (seeds shared per context and repeat, the "
            "pairing its statistics rely on). Re-run pipelines.evaluate into a new output folder")
    return pd.read_parquet(path)
