"""Inspect Robots' JSON `EvalLog`s → one row per trial (scene × epoch), a scene's metadata as RoboView's factor,
value and context.

An `EvalLog` (one per run; Inspect Robots' `EvalLog.from_dict`, which `read_eval_log` calls, reads it and refuses
a schema version it does not know) holds per scene (`samples[]`) its id, instruction, metadata and one dict of scores per epoch. Each row:
`task`, `policy`, `embodiment` (the run's `eval` spec), `log` (the file), `scene_id`, `instruction`, `epoch`,
`metadata.<key>` (the scene's metadata) and `score.<scorer>` (the epoch's score values). A trial that errored is
recorded by Inspect Robots with no scores and never scored; it is left out here as there.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pandas as pd

from roboview.eval.running.harnesses.base import HarnessTable, scalar_fields

logger = logging.getLogger(__name__)

# The scene-metadata keys factor, value and context default to; the scorer success defaults to.
FACTOR_KEY, VALUE_KEY, CONTEXT_KEY = "metadata.factor", "metadata.value", "metadata.context"
SUCCESS_SCORER = "success_at_end"
EXPECTED = "expected an Inspect Robots eval log (JSON, written into its log_dir) or a folder of them"


def read_inspect_robots(path: Path) -> HarnessTable:
    """Every scored trial of the eval log(s) `path` names or holds, mapped as docs/audit.md says."""
    from inspect_robots.log import SCHEMA_VERSION

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"--results={path}: no such file or folder; {EXPECTED}")
    candidates = sorted(path.glob("*.json")) if path.is_dir() else [path]
    rows, skipped, files = [], 0, []
    for file in candidates:
        log = _read(file, SCHEMA_VERSION, in_folder=path.is_dir())
        if log is None:
            continue
        files.append(file)
        for sample in log.samples:
            scene = {
                "task": log.eval.task,
                "policy": log.eval.policy,
                "embodiment": log.eval.embodiment,
                "log": file.name,
                "scene_id": sample.scene_id,
                "instruction": sample.instruction,
                **scalar_fields(sample.scene_metadata, "metadata."),
            }
            for epoch, scores in enumerate(sample.epochs):
                if not scores:
                    skipped += 1
                    continue
                rows.append({**scene, "epoch": epoch, **scalar_fields(scores, "score.")})
    if skipped:
        logger.info("%d trials errored and were never scored (Inspect Robots' rule); left out", skipped)
    if not files:
        raise ValueError(
            f"--results={path} holds no eval log (*.json with version, eval and samples); {EXPECTED}"
        )
    if not rows:
        raise ValueError(f"--results={path} holds no scored trial; {EXPECTED}")
    table = pd.DataFrame(rows)
    names = ", ".join(f.name for f in files)
    return _mapped(table, f"Inspect Robots eval logs {names}")


def _read(file: Path, supported: int, in_folder: bool):
    """The eval log in `file` through Inspect Robots' own reader; None for a folder's other JSON files."""
    from inspect_robots.log import EvalLog

    try:
        data = json.loads(file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        if in_folder:
            return None
        raise ValueError(f"--results={file} is not JSON ({str(exc).splitlines()[0]}); {EXPECTED}") from None
    if not isinstance(data, dict) or not {"version", "eval", "samples"} <= data.keys():
        if in_folder:
            return None
        raise ValueError(
            f"--results={file} is JSON but no eval log (no version, eval and samples); {EXPECTED}"
        )
    if data["version"] != supported:
        raise ValueError(
            f"--results={file}: Inspect Robots eval-log schema version {data['version']!r} is not supported; the "
            f"installed inspect-robots reads version {supported} (read it with the inspect-robots that wrote it)"
        )
    try:
        return EvalLog.from_dict(data)
    except (ValueError, TypeError, KeyError) as exc:
        raise ValueError(
            f"--results={file}: Inspect Robots' EvalLog.from_dict refused it ({type(exc).__name__}: {exc}); "
            f"{EXPECTED}"
        ) from None


def _mapped(table: pd.DataFrame, source: str) -> HarnessTable:
    # No default repeat: scenes sharing a value and context each run epochs 0, 1, …; file order numbers them apart.
    mapping = {"policy": "policy"}
    missing = {}
    metadata = [c for c in table.columns if c.startswith("metadata.")]
    for name, column in (("factor", FACTOR_KEY), ("value", VALUE_KEY), ("context", CONTEXT_KEY)):
        if column in table:
            mapping[name] = column
        else:
            missing[name] = (
                f"the scenes' metadata has no `{column.removeprefix('metadata.')}` key (their keys: "
                f"{', '.join(c.removeprefix('metadata.') for c in metadata) or 'none'})"
            )
    scores = [c for c in table.columns if c.startswith("score.")]
    if f"score.{SUCCESS_SCORER}" in table:
        mapping["success"] = f"score.{SUCCESS_SCORER}"
    elif len(scores) == 1:
        mapping["success"] = scores[0]
    else:
        missing["success"] = (
            f"the logs score with {', '.join(s.removeprefix('score.') for s in scores)} and none is "
            f"{SUCCESS_SCORER}: name the pass/fail one"
        )
    return HarnessTable(table, mapping, source, missing)
