"""gauntlet-robotics' `episodes.json` → one row per episode, its perturbation axes as RoboView's factor and value.

`gauntlet run SUITE.yaml --policy P --out DIR` (gauntlet-robotics 0.5.1) writes `DIR/episodes.json`: a JSON list of
its `Episode` records (`gauntlet.runner.episode.Episode`), one per episode of the suite's grid of cells, and beside it
`report.json` (its analysis, a JSON object) and `repro.json` (which names the policy). An episode holds `suite_name`,
`cell_index`, `episode_index`, `seed`, `perturbation_config` ({axis: value}; a categorical axis's value is the index
of its label in the suite YAML), `success`, `step_count`, and `gauntlet_version`, `suite_hash` and more.

Each row: the record's scalars, `axis.<name>` per axis, `factor` (the axes the run varies, "+"-joined), `value`
(the cell's values of those axes, "axis=value" joined), `context` (`suite_name`), `repeat` (`episode_index`) and
`policy` (from repro.json when it is there). gauntlet marks no episode as the unperturbed baseline, and its seeds
differ from cell to cell: its values are compared as independent samples, with no pairs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from roboview.eval.running.harnesses.base import HarnessTable, scalar_fields

FILE = "episodes.json"
REQUIRED = ("suite_name", "cell_index", "episode_index", "perturbation_config", "success")
EXPECTED = "expected gauntlet's episodes.json (a JSON list of episodes, written by `gauntlet run --out DIR`) or its DIR"


def read_gauntlet(path: Path) -> HarnessTable:
    """Every episode of a gauntlet run (its folder, or its episodes.json), mapped as the module says."""
    path = Path(path)
    file = path / FILE if path.is_dir() else path
    if not file.is_file():
        raise FileNotFoundError(f"--results={path}: no {FILE} there; {EXPECTED}")
    try:
        data = json.loads(file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"--results={file} is not JSON ({str(exc).splitlines()[0]}); {EXPECTED}") from None
    if isinstance(data, dict):
        raise ValueError(f"--results={file} is a JSON object (gauntlet's report.json is one); {EXPECTED}")
    if not isinstance(data, list) or not data:
        raise ValueError(f"--results={file} holds no episode; {EXPECTED}")
    rows = []
    for i, episode in enumerate(data):
        missing = [k for k in REQUIRED if not isinstance(episode, dict) or k not in episode]
        if missing:
            raise ValueError(f"--results={file}: episode {i} lacks {', '.join(missing)}; {EXPECTED}")
        axes = episode["perturbation_config"]
        if not isinstance(axes, dict) or not all(isinstance(v, (int, float)) for v in axes.values()):
            raise ValueError(
                f"--results={file}: episode {i}'s perturbation_config {axes!r} is not {{axis: number}}; {EXPECTED}"
            )
        rows.append(scalar_fields(episode) | {f"axis.{k}": float(v) for k, v in axes.items()})
    table = pd.DataFrame(rows)
    axes = sorted(c.removeprefix("axis.") for c in table.columns if c.startswith("axis."))
    varied = [a for a in axes if table[f"axis.{a}"].nunique() > 1] or axes
    table["factor"] = "+".join(varied)
    table["value"] = [",".join(f"{a}={r[f'axis.{a}']:g}" for a in varied) for _, r in table.iterrows()]
    mapping = {"factor": "factor", "value": "value", "context": "suite_name", "success": "success"}
    mapping["repeat"] = "episode_index"
    missing = {}
    repro = file.with_name("repro.json")
    policy = json.loads(repro.read_text()).get("policy") if repro.is_file() else None
    if policy:
        table["policy"] = str(policy)
        mapping["policy"] = "policy"
    else:
        missing["policy"] = "episodes.json names no policy and no repro.json lies beside it"
    versions = sorted({str(v) for v in table.get("gauntlet_version", pd.Series(dtype=str)).dropna()})
    source = f"gauntlet-robotics {', '.join(versions) or '(version not recorded)'} episodes {file.name} ({len(table)} episodes)"
    return HarnessTable(table, mapping, source, missing)
