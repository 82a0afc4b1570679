"""RoboView's statistics for any benchmark's per-episode results: is a drop real, or noise?

    roboview-audit --results=rollouts.csv --map.factor=category --map.value=variant \\
        --map.context=base_task --map.success=success [--map.repeat=trial] [--map.policy=model] \\
        --output_dir=outputs/audit
    roboview-audit --format=vla_eval|inspect_robots --results=FILE_OR_DIR --output_dir=outputs/audit

Reads one row per episode (CSV, parquet or JSON lines) from another benchmark — LIBERO-plus, VLA-Arena,
RoboTwin, your own logs — maps its columns onto RoboView's episode record and writes the same report.md
and metrics.json as `roboview.pipelines.report`: per factor the success rate per value, the noise floor
(`cv_null`), `cv_excess`, the GLM likelihood-ratio test of `value + context` against `context`, per-value
odds ratios with exact p- and q-values, and the power this design has against a bias of logit SD
`--tau`. With several policies (`--map.policy`), the paired comparisons too.

`--format` reads another harness's own files instead of a table: `vla_eval` (vla-eval's recording database or
exported aggregate JSON; LIBERO-plus, LIBERO-Pro and RoboTwin results map without --map flags) or
`inspect_robots` (Inspect Robots' JSON eval logs; the scenes' metadata keys factor, value and context). Any
--map.* flag overrides the harness's default column; roboview.eval.running.harnesses says what each column holds.

The mapping:

- `--map.factor`: the column naming what was perturbed (camera, light, language, …). One column may hold
  several factors: each becomes its own split. Or `--factor_name=NAME` when the file holds one factor.
- `--map.value`: the level of that factor (a camera variant, a light setting); its own SR is compared
  with the others'.
- `--map.context`: what the comparison is stratified by (the base task, the scene): values are compared
  within a context, never across (a hard task is not mistaken for a bad camera).
- `--map.success`: 1/0, true/false, yes/no or success/failure.
- `--map.repeat`: trial index; without it, episodes of one (policy, factor, value, context) are numbered
  in file order. Permutations shuffle value labels within (context, repeat): valid when a context's
  episodes are exchangeable across values under "the value does not matter" — true for i.i.d. trials,
  and exactly so when a repeat shares its seed across values, as RoboView's do.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.eval.reporting.report import REPORT_FILE, write_report
from roboview.eval.running.harnesses import harness_names, load
from roboview.eval.running.harnesses.base import MAP_FIELDS, REQUIRED, HarnessTable
from roboview.eval.statistics.metrics import MetricsConfig, policy_layouts
from roboview.eval.statistics.significance import lrt_power
from roboview.pipelines._cli import cli_main

METRICS_FILE = "metrics.json"
TRUE = {"1", "true", "yes", "success", "succeeded", "t", "y"}
FALSE = {"0", "false", "no", "failure", "fail", "failed", "f", "n"}


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


@dataclass
class AuditConfig:
    # Per-episode results: .csv, .parquet or .jsonl; with --format, the harness's file or folder.
    results: str = ""
    # Another harness's own results instead of a table: vla_eval or inspect_robots (docs/audit.md); empty: a
    # table mapped with --map.*. With a format, --map.* flags override its default columns.
    format: str = ""
    map: MapConfig = field(default_factory=MapConfig)
    # The factor's name when the file holds one factor and has no factor column.
    factor_name: str = ""
    # Policy name when the file has no policy column.
    policy_name: str = "policy"
    # Folder for report.md, metrics.json and plots.
    output_dir: str = "outputs/audit"
    # Bias size (logit SD of the value effects) the power line is computed for, as roboview.pipelines.plan.
    tau: float = 0.3
    # How the statistics are computed, as roboview.pipelines.report: --metrics.n_perm, --metrics.n_glm, --metrics.max_perm,
    # --metrics.seed, --metrics.epsilon (docs/statistics.md).
    metrics: MetricsConfig = field(default_factory=MetricsConfig)

    def __post_init__(self) -> None:
        if not self.tau > 0:
            raise ValueError(f"--tau={self.tau} must be > 0 (a logit SD, e.g. 0.3)")
        if self.format:
            load(self.format)
            if not self.results:
                raise ValueError(f"--results is required: the {self.format} results file or folder")
            if not Path(self.results).exists():
                raise ValueError(f"--results={self.results}: no such file or folder ({self.format} results)")
            return  # the mapping is checked once the harness's defaults are known
        if not self.results:
            raise ValueError("--results is required: a per-episode CSV, parquet or JSON-lines file")
        problem = input_problem(Path(self.results))
        if problem:
            raise ValueError(problem)
        missing = [f"--map.{k}" for k in ("value", "context", "success") if not getattr(self.map, k)]
        if not self.map.factor and not self.factor_name:
            missing.append("--map.factor (or --factor_name)")
        if missing:
            raise ValueError(
                f"missing {', '.join(missing)}: name the columns of {self.results} that hold them (or read "
                f"another harness's files with --format={'|'.join(harness_names())})"
            )


FORMATS = {".csv": "CSV", ".parquet": "parquet", ".jsonl": "JSON lines", ".json": "JSON lines"}
EXPECTED = "expected one row per episode in a .csv, .parquet or .jsonl file"


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


def _success(column: pd.Series, name: str) -> np.ndarray:
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


def to_episodes(table: pd.DataFrame, cfg: AuditConfig) -> pd.DataFrame:
    """RoboView episode records (policy, split, factor, value, context_id, instance_id, repeat, success)."""
    m = cfg.map
    columns = [c for c in (m.factor, m.value, m.context, m.success, m.repeat, m.policy) if c]
    missing = [c for c in columns if c not in table]
    if missing:
        raise ValueError(
            f"{cfg.results} has no column(s) {missing}; its columns: {', '.join(map(str, table.columns))}"
        )
    factor = table[m.factor].astype(str) if m.factor else pd.Series(cfg.factor_name, index=table.index)
    out = pd.DataFrame(
        {
            "policy": table[m.policy].astype(str) if m.policy else cfg.policy_name,
            "factor": factor.str.replace("|", "/", regex=False),
            "value": table[m.value].astype(str).str.replace("|", "/", regex=False),
            "context_id": table[m.context].astype(str),
            "success": _success(table[m.success], m.success),
        }
    )
    out["split"] = out["factor"]
    out["instance_id"] = [
        hashlib.sha256(f"{f}\0{v}\0{c}".encode()).hexdigest()[:16]
        for f, v, c in zip(out["factor"], out["value"], out["context_id"])
    ]
    if m.repeat:
        out["repeat"] = pd.factorize(table[m.repeat].astype(str), sort=True)[0]
        dup = out.duplicated(["policy", "instance_id", "repeat"])
        if dup.any():
            row = out[dup].iloc[0]
            raise ValueError(
                f"--map.repeat={m.repeat}: {int(dup.sum())} episodes repeat a (policy, factor, value, "
                f"context, repeat), e.g. {row['factor']}={row['value']} in {row['context_id']}"
            )
    else:
        out["repeat"] = out.groupby(["policy", "instance_id"]).cumcount()
    return out


def harness_map(cfg: AuditConfig, harness: HarnessTable) -> MapConfig:
    """The --map.* flags given, each empty one filled with the harness's default column; a field left without a
    column, or a column with episodes that lack a value, raises ValueError saying why and which flag names it."""
    given = {name: getattr(cfg.map, name) for name in MAP_FIELDS}
    columns = {name: given[name] or harness.mapping.get(name, "") for name in MAP_FIELDS}
    if cfg.factor_name and not given["factor"]:
        columns["factor"] = ""
    unmapped = [n for n in REQUIRED if not columns[n] and not (n == "factor" and cfg.factor_name)]
    table = harness.table
    if unmapped:
        by_reason: dict[str, list[str]] = {}
        for n in unmapped:
            by_reason.setdefault(harness.missing.get(n, "no default column"), []).append(n)
        reasons = "; ".join(f"{', '.join(names)}: {reason}" for reason, names in by_reason.items())
        flags = " ".join(f"--map.{n}=COLUMN" for n in unmapped)
        columns_read = list(map(str, table.columns))
        raise ValueError(
            f"--format={cfg.format} --results={cfg.results}: {reasons}. Name them with {flags}"
            + (" (or --factor_name=NAME)" if "factor" in unmapped else "")
            + f"; its columns: {', '.join(columns_read[:40])}{' …' if len(columns_read) > 40 else ''}"
        )
    for name in REQUIRED:
        column = columns[name]
        if column in table and table[column].isna().any():
            raise ValueError(
                f"--map.{name}={column}: {int(table[column].isna().sum())} of {len(table)} episodes of "
                f"{cfg.results} have no {column}; name another column with --map.{name}=COLUMN"
            )
    return MapConfig(**columns)


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


def run(cfg: AuditConfig):
    origin = f"`{cfg.results}`"
    if cfg.format:
        harness = load(cfg.format)(Path(cfg.results))
        cfg = replace(cfg, map=harness_map(cfg, harness))
        table, origin = harness.table, f"{origin} ({harness.source})"
    else:
        table = read_table(cfg.results)
    episodes = to_episodes(table, cfg)
    metrics_cfg = cfg.metrics
    source = {
        "path": str(cfg.results),
        "roboview_benchmark_version": None,
        "provenance": [],
        "mapping": {k: v for k, v in vars(cfg.map).items() if v},
    }
    if cfg.format:
        source["format"] = cfg.format
    result = write_report(episodes, cfg.output_dir, metrics_cfg, sources=[source], plots=False)
    power = power_lines(episodes, cfg.tau)
    for name, layout in policy_layouts(result.metrics).items():
        for split, m in layout["splits"].items():
            m["power"] = power.get(name, {}).get(split)
    out = Path(cfg.output_dir)
    (out / METRICS_FILE).write_text(json.dumps(result.metrics, indent=2, allow_nan=False) + "\n")
    lines = [
        "## Audit: mapping and power",
        "",
        f"Source {origin}: {len(episodes)} episodes; factor ← {cfg.map.factor or repr(cfg.factor_name)}, "
        f"value ← {cfg.map.value}, context ← {cfg.map.context}, success ← {cfg.map.success}, repeat ← "
        f"{cfg.map.repeat or 'file order'}, policy ← {cfg.map.policy or repr(cfg.policy_name)}.",
        "",
        "| policy | split | values | contexts | repeats | power at τ = " + f"{cfg.tau:g} |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for name, splits in power.items():
        for split, p in splits.items():
            lines.append(
                f"| {name} | {split} | {p['n_values']} | {p['n_contexts']} | {p['repeats']} | "
                + ("N/A" if p["power"] is None else f"{100 * p['power']:.2f}")
                + " |"
            )
    with (out / REPORT_FILE).open("a") as fh:
        fh.write("\n" + "\n".join(lines) + "\n")
    return result


def _summary(cfg: AuditConfig, result) -> None:
    print(
        f"[audit] {Path(cfg.output_dir) / REPORT_FILE} and {METRICS_FILE}: "
        + ", ".join(
            f"{name}/{split} p {m['p_value'] if m['p_value'] is None else f'{m["p_value"]:.3g}'}"
            for name, layout in policy_layouts(result.metrics).items()
            for split, m in layout["splits"].items()
        )
    )


def main(args: list[str] | None = None):
    return cli_main(AuditConfig, run, _summary, (ValueError, FileNotFoundError), args)


if __name__ == "__main__":
    main()
