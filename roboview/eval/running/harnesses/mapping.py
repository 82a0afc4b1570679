"""Any benchmark's per-episode results mapped onto RoboView's episode records: a table read from a CSV, parquet or
JSON-lines file (or a harness reader's table), its columns named for factor, value, context, success, repeat and
policy, turned into the rows RoboView's statistics read."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.eval.running.harnesses.base import MAP_FIELDS, REQUIRED, HarnessTable

TRUE = {"1", "true", "yes", "success", "succeeded", "t", "y"}
FALSE = {"0", "false", "no", "failure", "fail", "failed", "f", "n"}
FORMATS = {".csv": "CSV", ".parquet": "parquet", ".jsonl": "JSON lines", ".json": "JSON lines"}
EXPECTED = "expected one row per episode in a .csv, .parquet or .jsonl file"


@dataclass
class MapConfig:
    # Column naming the perturbed factor (one split per distinct name); or pass --factor_name.
    factor: str = ""
    # Column holding the factor's level.
    value: str = ""
    # Column the comparison is stratified by (base task, scene).
    context: str = ""
    # Column holding the episode's outcome (1/0, true/false, yes/no, success/failure).
    success: str = ""
    # Column numbering trials; empty: episodes of one (policy, factor, value, context) in file order.
    repeat: str = ""
    # Column naming the policy (several policies: paired comparisons); empty: --policy_name.
    policy: str = ""


def input_problem(path: Path) -> str | None:
    """Why `path` is not a per-episode file audit reads, in one line naming it and what was expected; None if it
    may be one (its contents are checked when read)."""
    from roboview.eval.running.inputs import benchmark_root, is_parquet, is_results_folder

    if not path.exists():
        return f"--results={path}: no such file; {EXPECTED}"
    if path.is_dir():
        if benchmark_root(path) == path:
            return (
                f"--results={path} is a benchmark folder (its instances), not per-episode results; {EXPECTED}"
            )
        if is_results_folder(path):
            return (
                f"--results={path} is a RoboView results folder: report it with roboview-report "
                f"--results={path / 'episodes.parquet'} (audit reads other benchmarks' per-episode files)"
            )
        return f"--results={path} is a folder; {EXPECTED}"
    if path.suffix.lower() not in FORMATS:
        return f"--results={path}: unknown format {path.suffix!r}; {EXPECTED}"
    if path.suffix.lower() == ".parquet" and not is_parquet(path):
        return f"--results={path} is named .parquet but its bytes are not parquet; {EXPECTED}"
    return None


def read_table(path: str) -> pd.DataFrame:
    """The per-episode table of a CSV, parquet or JSON-lines file; FileNotFoundError or ValueError saying why not."""
    file = Path(path)
    problem = input_problem(file)
    if problem:
        raise FileNotFoundError(problem) if not file.exists() else ValueError(problem)
    kind = FORMATS[file.suffix.lower()]
    try:
        if kind == "CSV":
            table = pd.read_csv(file)
        elif kind == "parquet":
            table = pd.read_parquet(file)
        else:
            table = pd.read_json(file, lines=True)
    except Exception as exc:  # pandas' and pyarrow's parse errors, undecodable bytes, an empty file
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(
            f"--results={path} could not be read as {kind} ({type(exc).__name__}: {reason}); {EXPECTED}"
        ) from None
    if table.empty:
        raise ValueError(f"--results={path} holds no rows; {EXPECTED}")
    return table


def outcomes(column: pd.Series, name: str) -> np.ndarray:
    """The success column as booleans (1/0, true/false, yes/no, success/failure); ValueError naming the others."""
    if column.dtype == bool:
        return column.to_numpy()
    text = column.astype(str).str.strip().str.lower().str.removesuffix(".0")
    bad = sorted(set(text) - TRUE - FALSE)
    if bad:
        raise ValueError(
            f"--map.success={name}: values {bad[:5]} are not outcomes; allowed: 1/0, true/false, "
            "yes/no, success/failure"
        )
    return text.isin(TRUE).to_numpy()


def to_episodes(
    table: pd.DataFrame, m: MapConfig, results: str, factor_name: str = "", policy_name: str = "policy"
) -> pd.DataFrame:
    """RoboView episode records (policy, split, factor, value, context_id, instance_id, repeat, success) of the
    table read from `results`: its columns as `m` names them, else `factor_name` and `policy_name` for every row."""
    columns = [c for c in (m.factor, m.value, m.context, m.success, m.repeat, m.policy) if c]
    missing = [c for c in columns if c not in table]
    if missing:
        raise ValueError(
            f"{results} has no column(s) {missing}; its columns: {', '.join(map(str, table.columns))}"
        )
    factor = table[m.factor].astype(str) if m.factor else pd.Series(factor_name, index=table.index)
    out = pd.DataFrame(
        {
            "policy": table[m.policy].astype(str) if m.policy else policy_name,
            "factor": factor.str.replace("|", "/", regex=False),
            "value": table[m.value].astype(str).str.replace("|", "/", regex=False),
            "context_id": table[m.context].astype(str),
            "success": outcomes(table[m.success], m.success),
        }
    )
    out["split"] = out["factor"]
    out["instance_id"] = [
        hashlib.sha256(f"{f}\0{v}\0{c}".encode()).hexdigest()[:16]
        for f, v, c in zip(out["factor"], out["value"], out["context_id"])
    ]
    out["repeat"] = _repeats(table, out, m.repeat)
    return out


def _repeats(table: pd.DataFrame, episodes: pd.DataFrame, column: str) -> np.ndarray:
    """The trial index of every episode: the `column`'s values numbered, or file order within each instance."""
    if not column:
        return episodes.groupby(["policy", "instance_id"]).cumcount().to_numpy()
    repeat = pd.factorize(table[column].astype(str), sort=True)[0]
    dup = episodes.assign(repeat=repeat).duplicated(["policy", "instance_id", "repeat"])
    if dup.any():
        row = episodes[dup].iloc[0]
        raise ValueError(
            f"--map.repeat={column}: {int(dup.sum())} episodes repeat a (policy, factor, value, "
            f"context, repeat), e.g. {row['factor']}={row['value']} in {row['context_id']}"
        )
    return repeat


def harness_map(
    given: MapConfig, harness: HarnessTable, harness_name: str, results: str, factor_name: str = ""
) -> MapConfig:
    """The --map.* flags given, each empty one filled with the harness's default column; a field left without a
    column, or a column with episodes that lack a value, raises ValueError saying why and which flag names it.
    `harness_name` and `results` (the --format and the --results read) name the harness's results in the
    messages."""
    columns = {name: getattr(given, name) or harness.mapping.get(name, "") for name in MAP_FIELDS}
    if factor_name and not given.factor:
        columns["factor"] = ""
    unmapped = [n for n in REQUIRED if not columns[n] and not (n == "factor" and factor_name)]
    table = harness.table
    if unmapped:
        by_reason: dict[str, list[str]] = {}
        for n in unmapped:
            by_reason.setdefault(harness.missing.get(n, "no default column"), []).append(n)
        reasons = "; ".join(f"{', '.join(names)}: {reason}" for reason, names in by_reason.items())
        flags = " ".join(f"--map.{n}=COLUMN" for n in unmapped)
        columns_read = list(map(str, table.columns))
        raise ValueError(
            f"--format={harness_name} --results={results}: {reasons}. Name them with {flags}"
            + (" (or --factor_name=NAME)" if "factor" in unmapped else "")
            + f"; its columns: {', '.join(columns_read[:40])}{' …' if len(columns_read) > 40 else ''}"
        )
    for name in REQUIRED:
        column = columns[name]
        if column in table and table[column].isna().any():
            raise ValueError(
                f"--map.{name}={column}: {int(table[column].isna().sum())} of {len(table)} episodes of "
                f"{results} have no {column}; name another column with --map.{name}=COLUMN"
            )
    return MapConfig(**columns)
