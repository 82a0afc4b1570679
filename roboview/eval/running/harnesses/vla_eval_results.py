"""vla-eval's per-episode results → one row per episode, with LIBERO-plus', LIBERO-Pro's and RoboTwin's perturbation
fields as RoboView's factor, value and context.

vla-eval records every episode in a SQLite database, `recording-<eval-id>.sqlite` (table `episode_results`: one
row per episode, its task's fields as the episode's context), and `vla-eval export` writes it out as
`<benchmark>_aggregate.json` (`tasks[].episodes[]`, each episode with those fields) plus one JSONL file of step
rows per episode. A database is read through vla-eval's own exporter (`vla_eval.results.export.export_db`, into a
scratch folder: a consistent snapshot, the last attempt of a retried episode); an aggregate is read as the JSON it
is. Each row: the episode's fields (`name`, `suite`, `task_id`, `category`, `difficulty_level`, `episode_id`, …),
`metrics.<key>`, the benchmark entry's constructor arguments as `params.<key>`, `benchmark`, `eval_id`, `task`,
`source` (the file) and `success` (vla-eval's own rule: `metrics.success`; an episode that errored counts as a
failure, as vla-eval counts it).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import tempfile
from pathlib import Path

import pandas as pd

from roboview.eval.running.harnesses.base import HarnessTable, scalar_fields

logger = logging.getLogger(__name__)

RECORDING_GLOB = "recording-*.sqlite"
AGGREGATE_GLOB = "*_aggregate.json"
SQLITE_MAGIC = b"SQLite format 3\x00"
# LIBERO-plus' category whose variants rewrite the instruction itself: the instruction names no base task there.
LANGUAGE_CATEGORY = "language"
EXPECTED = (
    "expected vla-eval's recording-<eval-id>.sqlite, an exported <benchmark>_aggregate.json, or the "
    "--output-dir folder of a vla-eval run holding them"
)


def read_vla_eval(path: Path) -> HarnessTable:
    """Every episode `path` holds (a recording, an aggregate, or a run folder), mapped as docs/audit.md says."""
    bodies = read_results(path)
    table = _episodes(bodies, path)
    return _mapped(table, ", ".join(sorted({name for name, _ in bodies})))


def read_results(path: Path) -> list[tuple[str, dict]]:
    """(file name, benchmark aggregate with its episodes) of every vla-eval result `path` names or holds: its
    recordings, through vla-eval's own exporter, else its exported aggregate JSONs (also roboview.integrations.vla_eval's)."""
    recordings, aggregates = _sources(Path(path))
    bodies: list[tuple[str, dict]] = []
    if recordings:
        if aggregates:
            logger.info(
                "reading %s; %s beside it, its export, not read again",
                ", ".join(r.name for r in recordings),
                ", ".join(a.name for a in aggregates),
            )
        for db in recordings:
            bodies += [(db.name, body) for body in _export(db)]
    else:
        bodies = [(file.name, _aggregate(file)) for file in aggregates]
    for name, body in bodies:
        if body.get("partial"):
            logger.warning(
                "%s: %s is partial (work items never finished); auditing the episodes it holds",
                name,
                body.get("benchmark"),
            )
    return bodies


def _sources(path: Path) -> tuple[list[Path], list[Path]]:
    """(recordings, aggregates) `path` names or holds."""
    if not path.exists():
        raise FileNotFoundError(f"--results={path}: no such file or folder; {EXPECTED}")
    if path.is_dir():
        recordings, aggregates = sorted(path.glob(RECORDING_GLOB)), sorted(path.glob(AGGREGATE_GLOB))
        if not recordings and not aggregates:
            raise ValueError(f"--results={path} holds no {RECORDING_GLOB} or {AGGREGATE_GLOB}; {EXPECTED}")
        return recordings, aggregates
    with path.open("rb") as fh:
        head = fh.read(len(SQLITE_MAGIC))
    if head == SQLITE_MAGIC:
        return [path], []
    if path.suffix.lower() == ".json":
        return [], [path]
    if path.suffix.lower() == ".jsonl":
        raise ValueError(
            f"--results={path} is a JSON-lines file: vla-eval's per-episode JSONL holds one episode's step rows, "
            f"not its task or outcome; {EXPECTED}"
        )
    raise ValueError(f"--results={path} is neither a SQLite database nor JSON; {EXPECTED}")


def _export(db: Path) -> list[dict]:
    """The recording's benchmark aggregates (episodes included), as `vla-eval export` builds them."""
    from vla_eval.results.export import export_db

    with tempfile.TemporaryDirectory(prefix="roboview-vla-eval-") as scratch:
        try:
            return export_db(db, Path(scratch))
        except (sqlite3.Error, OSError, ValueError, KeyError, TypeError) as exc:
            reason = (str(exc).strip().splitlines() or [""])[0]
            raise ValueError(
                f"--results={db}: vla-eval's exporter could not read it ({type(exc).__name__}: {reason}); "
                f"{EXPECTED}"
            ) from None


def _aggregate(file: Path) -> dict:
    try:
        body = json.loads(file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"--results={file} is not JSON ({str(exc).splitlines()[0]}); {EXPECTED}") from None
    if not isinstance(body, dict) or not isinstance(body.get("tasks"), list):
        raise ValueError(f"--results={file} is JSON but no vla-eval result (no `tasks` list); {EXPECTED}")
    return body


def _episodes(bodies: list[tuple[str, dict]], path: Path) -> pd.DataFrame:
    rows = []
    for source, body in bodies:
        params = scalar_fields((body.get("config") or {}).get("params") or {}, "params.")
        for task in body["tasks"]:
            for episode in task.get("episodes") or []:
                metrics = episode.get("metrics") if isinstance(episode.get("metrics"), dict) else {}
                row = {
                    **params,
                    **scalar_fields(episode),
                    **scalar_fields(metrics, "metrics."),
                    "source": source,
                    "benchmark": body.get("benchmark"),
                    "eval_id": body.get("eval_id", ""),
                    "task": task.get("task"),
                }
                if "success" in metrics:
                    row["success"] = bool(metrics["success"])
                rows.append(row)
    if not rows:
        raise ValueError(f"--results={path} holds no episodes; {EXPECTED}")
    table = pd.DataFrame(rows)
    if "success" in table:
        # An episode recorded without a success metric failed before the benchmark scored it.
        table["success"] = table["success"].fillna(False).astype(bool)
    errored = int(table["failure_reason"].notna().sum()) if "failure_reason" in table else 0
    if errored:
        logger.info(
            "%d episodes errored (failure_reason); counted as failures, as vla-eval counts them", errored
        )
    return table


def _libero_pro_split(suite: object) -> tuple[str, str]:
    """(base suite, perturbation) of a LIBERO-Pro suite name, by LIBERO-Pro's own rule ("" for a base suite)."""
    from vla_eval.benchmarks.libero_pro.benchmark import LIBEROProBenchmark

    if not isinstance(suite, str):
        return "", ""
    base = LIBEROProBenchmark._infer_base_suite(suite)
    return base, suite[len(base) + 1 :] if suite != base else ""


def _mapped(table: pd.DataFrame, source: str) -> HarnessTable:
    mapping = {"context": "task"}
    missing = {}
    if "success" in table:
        mapping["success"] = "success"
    else:
        metrics = [c for c in table.columns if c.startswith("metrics.")]
        missing["success"] = (
            f"the episodes record no `success` metric (theirs: {', '.join(metrics) or 'none'}); name the "
            "outcome column"
        )
    if "category" in table and table["category"].notna().any():
        unclassified = table["category"].isna()
        if unclassified.any():
            suites = sorted(table.loc[unclassified, "suite"].astype(str).unique()) if "suite" in table else []
            raise ValueError(
                f"{int(unclassified.sum())} LIBERO-plus episodes have no `category` (suite {', '.join(suites)}: "
                "LIBERO-plus classifies libero_spatial, libero_object, libero_goal and libero_10 only); audit "
                "them apart"
            )
        language = table["category"].astype(str).str.lower().str.contains(LANGUAGE_CATEGORY)
        table["base_task"] = table["name"].where(~language, table["suite"])
        mapping.update(factor="category", value="difficulty_level", context="base_task")
        return HarnessTable(table, mapping, f"vla-eval LIBERO-plus results in {source}", missing)
    if "suite" in table:
        split = table["suite"].map(_libero_pro_split)
        if split.map(lambda s: bool(s[1])).any():
            table["base_suite"] = [base or suite for (base, _), suite in zip(split, table["suite"])]
            table["perturbation"] = [p or "none" for _, p in split]
            table["factor"] = "perturbation"
            if "task_id" in table:
                table["base_task"] = table["base_suite"] + "/" + table["task_id"].astype(str)
            mapping.update(factor="factor", value="perturbation", context="base_suite")
            return HarnessTable(table, mapping, f"vla-eval LIBERO-Pro results in {source}", missing)
        if "params.task_config" in table and (table["suite"] == "robotwin").all():
            table["factor"] = "task_config"
            mapping.update(factor="factor", value="params.task_config", context="task")
            return HarnessTable(table, mapping, f"vla-eval RoboTwin results in {source}", missing)
    # RoboView's own benchmark, run inside vla-eval.
    if {"context_id", "split", "value"} <= set(table.columns):
        mapping.update(factor="split", value="value", context="context_id", repeat="repeat")
        return HarnessTable(table, mapping, f"vla-eval RoboView results in {source}", missing)
    fields = [c for c in table.columns if not c.startswith(("metrics.", "params."))]
    why = (
        f"these vla-eval episodes ({', '.join(sorted(table['benchmark'].astype(str).unique()))}) carry no "
        "perturbation field: no LIBERO-plus `category`, no LIBERO-Pro perturbed `suite` "
        "(libero_<suite>_<perturbation>), no RoboTwin `params.task_config` (their fields: "
        f"{', '.join(fields)})"
    )
    missing.update(factor=why, value=why)
    return HarnessTable(table, mapping, f"vla-eval results in {source}", missing)
