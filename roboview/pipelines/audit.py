"""RoboView's statistics for any benchmark's per-episode results: is a drop real, or noise?

    roboview-audit --results=rollouts.csv --map.factor=category --map.value=variant \\
        --map.context=base_task --map.success=success [--map.repeat=trial] [--map.policy=model] \\
        --output_dir=outputs/audit
    roboview-audit --format=vla_eval|inspect_robots|gauntlet|xevals --results=FILE_OR_DIR --output_dir=outputs/audit

Reads one row per episode (CSV, parquet or JSON lines) from another benchmark — LIBERO-plus, VLA-Arena,
RoboTwin, your own logs — maps its columns onto RoboView's episode record and writes the same report.md
and metrics.json as `roboview.pipelines.report`: per factor the success rate per value, the noise floor
(`cv_null`), `cv_excess`, the GLM likelihood-ratio test of `value + context` against `context`, per-value
odds ratios with exact p- and q-values, and the power this design has against a bias of logit SD
`--tau`. With several policies (`--map.policy`), the paired comparisons too.

`--format` reads another harness's own files instead of a table: `vla_eval` (vla-eval's recording database or
exported aggregate JSON; LIBERO-plus, LIBERO-Pro and RoboTwin results map without --map flags),
`inspect_robots` (Inspect Robots' JSON eval logs; the scenes' metadata keys factor, value and context), `gauntlet`
(gauntlet-robotics' episodes.json: its perturbation axes) or `xevals` (xevals' run.json: a cell's perturbation and
severity). Any
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

from dataclasses import dataclass, field, replace
from pathlib import Path

from roboview.eval.campaign.audit import AuditSource, audit
from roboview.eval.reporting.report import METRICS_FILE, REPORT_FILE
from roboview.eval.running.harnesses import harness_names, load
from roboview.eval.running.harnesses.mapping import (
    MapConfig,
    harness_map,
    input_problem,
    read_table,
    to_episodes,
)
from roboview.eval.statistics.metrics import MetricsConfig, policy_layouts
from roboview.pipelines._cli import cli_main


@dataclass
class AuditConfig:
    # Per-episode results: .csv, .parquet or .jsonl; with --format, the harness's file or folder.
    results: str = ""
    # Another harness's own results instead of a table (docs/audit.md); empty: a table mapped with --map.*. With a
    # format, --map.* flags override its default columns.
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
    # --metrics.max_glm,
    # --metrics.seed, --metrics.epsilon (docs/statistics.md).
    metrics: MetricsConfig = field(default_factory=MetricsConfig)

    help_details = {"format": lambda: f"One of: {', '.join(harness_names())}."}

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


def run(cfg: AuditConfig):
    origin = f"`{cfg.results}`"
    if cfg.format:
        harness = load(cfg.format)(Path(cfg.results))
        cfg = replace(cfg, map=harness_map(cfg.map, harness, cfg.format, cfg.results, cfg.factor_name))
        table, origin = harness.table, f"{origin} ({harness.source})"
    else:
        table = read_table(cfg.results)
    episodes = to_episodes(table, cfg.map, cfg.results, cfg.factor_name, cfg.policy_name)
    source = AuditSource(cfg.results, origin, cfg.map, cfg.format, cfg.factor_name, cfg.policy_name)
    return audit(episodes, source, cfg.output_dir, cfg.metrics, cfg.tau)


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
