"""RoboView's report of another benchmark's episodes (mapped by roboview.eval.running.harnesses.mapping): the
statistics of roboview-report, each split's power against a bias of logit SD τ, and a section saying how the
columns were mapped."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.eval.reporting.report import METRICS_FILE, REPORT_FILE, ReportResult, write_report
from roboview.eval.running.harnesses.mapping import MapConfig
from roboview.eval.statistics.metrics import MetricsConfig, policy_layouts
from roboview.eval.statistics.significance import lrt_power


@dataclass(frozen=True)
class AuditSource:
    """What was audited: the results path, how the report names it, the harness format (empty: a mapped table),
    the columns mapped and the names given for a missing factor or policy column."""

    path: str
    origin: str
    columns: MapConfig
    format: str = ""
    factor_name: str = ""
    policy_name: str = "policy"

    def record(self) -> dict:
        """The report's source entry."""
        source = {
            "path": str(self.path),
            "roboview_benchmark_version": None,
            "provenance": [],
            "mapping": {k: v for k, v in vars(self.columns).items() if v},
        }
        return source | ({"format": self.format} if self.format else {})


def power_lines(episodes: pd.DataFrame, tau: float) -> dict[str, dict[str, dict]]:
    """policy → split → the design's power against a logit-SD `tau` bias (asymptotic LRT, as roboview.pipelines.plan)."""
    out: dict[str, dict[str, dict]] = {}
    for (policy, split), rows in episodes.groupby(["policy", "split"], sort=False):
        n_values, n_contexts = rows["value"].nunique(), rows["context_id"].nunique()
        repeats = int(round(len(rows) / max(1, n_values * n_contexts)))
        sr = float(np.clip(rows["success"].mean(), 0.02, 0.98))
        power = lrt_power(n_values, n_contexts, max(1, repeats), tau, sr) if n_values > 1 else None
        out.setdefault(str(policy), {})[str(split)] = {
            "tau": tau,
            "n_values": int(n_values),
            "n_contexts": int(n_contexts),
            "repeats": repeats,
            "power": power,
        }
    return out


def audit(
    episodes: pd.DataFrame, source: AuditSource, output_dir: str | Path, metrics: MetricsConfig, tau: float
) -> ReportResult:
    """Write report.md and metrics.json of the episodes to `output_dir`, each split's power in metrics.json and
    the mapping and power section at the end of report.md."""
    result = write_report(episodes, output_dir, metrics, sources=[source.record()], plots=False)
    power = power_lines(episodes, tau)
    for name, layout in policy_layouts(result.metrics).items():
        for split, m in layout["splits"].items():
            m["power"] = power.get(name, {}).get(split)
    out = Path(output_dir)
    (out / METRICS_FILE).write_text(json.dumps(result.metrics, indent=2, allow_nan=False) + "\n")
    with (out / REPORT_FILE).open("a") as fh:
        fh.write("\n" + "\n".join(_section(source, len(episodes), power, tau)) + "\n")
    return result


def _section(
    source: AuditSource, n_episodes: int, power: dict[str, dict[str, dict]], tau: float
) -> list[str]:
    """The report's "Audit: mapping and power" lines."""
    m = source.columns
    lines = [
        "## Audit: mapping and power",
        "",
        f"Source {source.origin}: {n_episodes} episodes; factor ← {m.factor or repr(source.factor_name)}, "
        f"value ← {m.value}, context ← {m.context}, success ← {m.success}, repeat ← "
        f"{m.repeat or 'file order'}, policy ← {m.policy or repr(source.policy_name)}.",
        "",
        "| policy | split | values | contexts | repeats | power at τ = " + f"{tau:g} |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for name, splits in power.items():
        for split, p in splits.items():
            lines.append(
                f"| {name} | {split} | {p['n_values']} | {p['n_contexts']} | {p['repeats']} | "
                + ("N/A" if p["power"] is None else f"{100 * p['power']:.2f}")
                + " |"
            )
    return lines
