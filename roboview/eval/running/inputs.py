"""What a path given to `report`, `audit`, `verify` or `merge` is, and a one-line error when it is not what the
command reads: a results folder or its `episodes.parquet`, a benchmark folder (or one of its tables), the
journal `episodes.jsonl`, another file format, or bytes that are none of these. Nothing here reads more than a
file's first and last bytes, its parquet footer or a folder's listing.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq

from roboview.benchmark.format import MANIFEST
from roboview.core.folders import folder_problem
from roboview.eval.running.results import FORMAT_KEY, JOURNAL, PARQUET, RUN_FILE

PARQUET_MAGIC = b"PAR1"
RESULTS_COLUMNS = ("instance_id", "repeat", "split", "value", "success")  # columns every results table holds
EXPECTED_FILE = "expected the episodes.parquet that roboview.pipelines.evaluate writes into its --output_dir"
EXPECTED_FOLDER = "expected a results folder (roboview.pipelines.evaluate's --output_dir, holding run.json and episodes.parquet)"


def benchmark_root(path: Path) -> Path | None:
    """The benchmark folder `path` is or lies in (up to two levels down: data/<split>.parquet), else None."""
    for folder in [path, *list(path.parents)[:2]]:
        if (folder / MANIFEST).is_file():
            return folder
    return None


def is_results_folder(path: Path) -> bool:
    return path.is_dir() and any((path / name).is_file() for name in (RUN_FILE, PARQUET, JOURNAL))


def is_parquet(path: Path) -> bool:
    """Whether the file starts and ends with parquet's magic bytes."""
    try:
        with path.open("rb") as fh:
            head = fh.read(4)
            if path.stat().st_size < 8:
                return False
            fh.seek(-4, 2)
            return head == PARQUET_MAGIC and fh.read(4) == PARQUET_MAGIC
    except OSError:
        return False


def _benchmark_hint(root: Path) -> str:
    return (
        f"evaluate a policy on it (roboview-evaluate --benchmark.path={root} --policy.type=NAME "
        "--output_dir=OUT) and pass OUT/episodes.parquet"
    )


def results_file(path: str | Path) -> Path:
    """The results parquet `path` names: the file itself, or `episodes.parquet` of a results folder (accepted in
    its place). Raises ValueError with one line naming `path` and what was expected when it is neither."""
    path = Path(path)
    if is_results_folder(path):
        file = path / PARQUET
        if not file.is_file():
            raise ValueError(
                f"{path} is a results folder without {PARQUET} yet (it is written while "
                "roboview.pipelines.evaluate runs and when it ends); rerun the same evaluate command to finish it"
            )
        path = file
    problem = results_file_problem(path)
    if problem:
        raise ValueError(problem)
    return path


def results_file_problem(path: Path) -> str | None:
    """Why `path` is not a RoboView results parquet, in one line; None when it is one (or an older results
    format, which `roboview.eval.running.results.read_episodes` refuses with its own message)."""
    root = benchmark_root(path)
    if not path.exists():
        return f"{path} does not exist; {EXPECTED_FILE}"
    if path.is_dir():
        if root == path:
            return f"{path} is a benchmark folder (roboview.pipelines.build_benchmark), not results: {_benchmark_hint(path)}"
        return f"{path} is a folder that holds no results ({RUN_FILE}, {PARQUET}); {EXPECTED_FILE}"
    if root is not None:
        return (
            f"{path} is a table of the benchmark {root} (its instances), not results: {_benchmark_hint(root)}"
        )
    if path.name == JOURNAL or (path.suffix == ".jsonl" and is_results_folder(path.parent)):
        finished = path.parent / PARQUET
        return (
            f"{path} is the journal roboview.pipelines.evaluate appends to while it runs, not the results table: pass "
            + (
                f"{finished}"
                if finished.is_file()
                else f"{finished} (not written yet: rerun the same evaluate command to finish the run)"
            )
        )
    if not is_parquet(path):
        kind = {
            ".csv": "a CSV file",
            ".jsonl": "a JSON-lines file",
            ".json": "a JSON file",
            ".parquet": "a file named .parquet whose bytes are not parquet",
        }.get(path.suffix.lower(), "not a parquet file")
        other = (
            " (another benchmark's per-episode CSV or JSON lines: roboview.pipelines.audit)"
            if path.suffix.lower() in (".csv", ".jsonl", ".json")
            else ""
        )
        return f"{path} is {kind}; {EXPECTED_FILE}{other}"
    try:
        schema = pq.read_schema(path)
    except Exception as exc:  # a damaged footer
        return f"{path} is not a readable parquet file ({type(exc).__name__}: {str(exc).splitlines()[0]}); {EXPECTED_FILE}"
    if (schema.metadata or {}).get(FORMAT_KEY) is None:
        missing = [c for c in RESULTS_COLUMNS if c not in schema.names]
        if missing:
            return (
                f"{path} is a parquet file but not RoboView results (no column(s) {', '.join(missing)}); "
                f"{EXPECTED_FILE}"
            )
    return None


def results_folder_problem(path: Path, benchmark_hint: str = "") -> str | None:
    """Why `path` is not a RoboView results folder, in one line; None when it is one. `benchmark_hint` follows
    "not results" when `path` is a benchmark folder (what the command does with one)."""
    if path.is_file() and is_results_folder(path.parent) and path.name in (PARQUET, JOURNAL, RUN_FILE):
        return f"{path} is a file of a results folder: pass the folder, {path.parent}"
    if path.is_dir() and benchmark_root(path) == path:
        return f"{path} is a benchmark folder (roboview.pipelines.build_benchmark), not results{benchmark_hint}; {EXPECTED_FOLDER}"
    problem = folder_problem(path, "results", RUN_FILE, EXPECTED_FOLDER)
    if problem:
        return problem
    try:
        run = json.loads((path / RUN_FILE).read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        return f"{path / RUN_FILE} is not JSON ({str(exc).splitlines()[0]}); {EXPECTED_FOLDER}"
    if not isinstance(run, dict):
        return f"{path / RUN_FILE} is not a run record (a JSON object); {EXPECTED_FOLDER}"
    if (path / PARQUET).is_file():
        problem = results_file_problem(path / PARQUET)
        if problem:
            return problem
    return None


def benchmark_folder_problem(path: Path) -> str | None:
    """Why `path` is not a benchmark folder, in one line; None when it holds a benchmark manifest."""
    expected = "expected a benchmark folder (roboview.pipelines.build_benchmark's --output_dir, holding benchmark.json)"
    root = benchmark_root(path.parent) if path.is_file() else None
    if not (path / MANIFEST).is_file() and is_results_folder(path):
        return f"{path} is a results folder (roboview.pipelines.evaluate), not a benchmark: verify it with --results={path}"
    advice = f"pass the benchmark folder, {root}" if root else expected
    return folder_problem(path, "benchmark", MANIFEST, advice)
