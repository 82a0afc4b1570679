"""xevals' `run.json` → one row per episode of each cell, the cell's perturbation as RoboView's factor and its
severity as the value.

`xevals.evaluate(...)` / `xevals run` (xevals 0.1.0) writes a run folder `<name>-<config hash>/` whose `run.json`
(`Result.save`; `"schema": 1`) lists the suite's cells (`suite.cells[]`: `name`, `perturbation` — a registered
name, or `none` for the clean cell —, `severity`, `split`) and, per cell and metric, `per_episode` values
(`cells[<cell>]["accuracy/success_rate"]["per_episode"]`: 1.0 or 0.0 per episode, in episode order). Every cell runs
the same seeds, so episode i of two cells is a pair.

Each row: `cell`, `perturbation`, `severity`, `split`, `episode` (its index), `success`, `suite` and `policy` (the run's
`model` type); `factor` is the perturbation, `value` the severity. The clean cell is every factor's baseline, at
severity 0: its episodes appear once under each perturbation the run holds, as RoboView's baseline appears in each
split. A cell whose per-episode success xevals did not keep (a paired or pooled metric) is refused.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from roboview.eval.running.harnesses.base import HarnessTable

FILE = "run.json"
SUCCESS = "accuracy/success_rate"
SCHEMA = 1
EXPECTED = "expected xevals' run.json (written into its run folder by Result.save) or that folder"


def read_xevals(path: Path) -> HarnessTable:
    """Every episode of an xevals run (its folder, or its run.json), mapped as the module says."""
    path = Path(path)
    file = path / FILE if path.is_dir() else path
    if not file.is_file():
        raise FileNotFoundError(f"--results={path}: no {FILE} there; {EXPECTED}")
    try:
        run = json.loads(file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"--results={file} is not JSON ({str(exc).splitlines()[0]}); {EXPECTED}") from None
    if not isinstance(run, dict) or not {"schema", "suite", "cells"} <= run.keys():
        raise ValueError(
            f"--results={file} is JSON but no xevals run (no schema, suite and cells); {EXPECTED}"
        )
    if run["schema"] != SCHEMA:
        raise ValueError(
            f"--results={file}: xevals run schema {run['schema']!r} is not supported; this reader knows schema {SCHEMA}"
        )
    cells = run["suite"].get("cells") or []
    clean = [c for c in cells if c.get("perturbation") == "none"]
    perturbations = sorted({c["perturbation"] for c in cells if c.get("perturbation") != "none"})
    if not clean or not perturbations:
        raise ValueError(f"--results={file}: the run needs its clean cell and a perturbed one; {EXPECTED}")
    policy = str((run.get("model") or {}).get("type") or "policy")
    rows = []
    for cell in cells:
        success = (run["cells"].get(cell["name"]) or {}).get(SUCCESS) or {}
        per_episode = success.get("per_episode")
        if per_episode is None:
            raise ValueError(
                f"--results={file}: cell {cell['name']!r} keeps no per-episode {SUCCESS}; {EXPECTED}"
            )
        for factor in perturbations if cell in clean else [cell["perturbation"]]:
            rows += [
                {
                    "cell": cell["name"],
                    "perturbation": cell["perturbation"],
                    "severity": float(cell.get("severity") or 0.0),
                    "split": cell.get("split", "in"),
                    "episode": i,
                    "success": bool(value),
                    "suite": run["suite"].get("name", ""),
                    "policy": policy,
                    "factor": factor,
                    "value": f"{float(cell.get('severity') or 0.0):g}",
                }
                for i, value in enumerate(per_episode)
            ]
    table = pd.DataFrame(rows)
    mapping = {
        "factor": "factor",
        "value": "value",
        "context": "suite",
        "success": "success",
        "repeat": "episode",
        "policy": "policy",
    }
    return HarnessTable(table, mapping, f"xevals run {file.parent.name}/{file.name} ({len(cells)} cells)")
