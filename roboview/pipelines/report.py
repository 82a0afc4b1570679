"""Turn evaluation episodes into metrics.json, report.md, report.html and plots.

    roboview-report --results=outputs/eval/episodes.parquet --output_dir=outputs/report

`--results` takes one parquet file or several, comma-separated (say one per policy); a results folder
stands for its episodes.parquet, and a file may also hold several policies. Metrics follow docs/formats.md, "Metrics" (roboview.eval.statistics.metrics); for several
policies metrics.json holds {"epsilon", "resampling", "sources", "policies": {name: metrics}}.
Inputs are checked before any work: missing files or columns, repeated episodes, mixed benchmark
versions, and paths that are not results (the journal episodes.jsonl, a benchmark folder or table, a CSV,
bytes that are not parquet) stop the run with one line naming the offender and what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.reporting.report import HTML_FILE, REPORT_FILE, ReportResult, load_results, write_report
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig, compute_all_metrics
from roboview.pipelines._cli import cli_main, result_entries


@dataclass
class ReportConfig:
    # Episode table(s) written by roboview.pipelines.evaluate: one path or several, comma-separated; NAME=PATH
    # names the file's policy in the report (e.g. act_ref=A.parquet,act_campose=B.parquet).
    results: str = ""
    # Folder that receives metrics.json, report.md, report.html (one self-contained page) and the PNG plots.
    output_dir: str = "outputs/report"
    # How the statistics are computed: --metrics.n_perm, --metrics.n_glm, --metrics.max_perm, --metrics.max_glm,
    # --metrics.seed, --metrics.epsilon (docs/statistics.md).
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    # Draw the PNG plots (false: metrics.json and report.md only).
    plots: bool = True
    # For each value that differs from its control arm (p < 0.05), replay this many of its discordant pairs here
    # (the recorded policy, the benchmark its provenance names) and show each as a strip of frames; 0: none.
    strips: int = 1

    def __post_init__(self) -> None:
        if self.strips < 0:
            raise ValueError(f"--strips={self.strips} must be 0 or more")
        if not self.result_paths:
            raise ValueError(
                "--results is required: the episodes.parquet file(s) of roboview.pipelines.evaluate"
            )

    @property
    def result_entries(self) -> list[tuple[str | None, Path]]:
        """(name or None, path) per entry; NAME=PATH renames the file's policy."""
        return result_entries(self.results)

    @property
    def result_paths(self) -> list[Path]:
        return [path for _, path in self.result_entries]


def run(cfg: ReportConfig) -> ReportResult:
    episodes, sources = load_results(cfg.result_paths, [name for name, _ in cfg.result_entries])
    metrics = compute_all_metrics(episodes, cfg.metrics)
    if cfg.strips:
        from roboview.eval.verification.pairs import make_strips

        out = Path(cfg.output_dir)
        out.mkdir(parents=True, exist_ok=True)
        strips = make_strips(metrics, sources, out, cfg.strips)
        if strips["drawn"] or strips["skipped"]:
            metrics["strips"] = strips
    return write_report(
        episodes, cfg.output_dir, cfg.metrics, sources=sources, plots=cfg.plots, metrics=metrics
    )


def _summary(cfg: ReportConfig, result: ReportResult) -> None:
    skipped = [name for name, reason in result.plots.items() if reason is not None]
    print(
        f"[report] {result.output_dir / REPORT_FILE} and {HTML_FILE}: {len(result.plots) - len(skipped)} plot(s) written"
        + (f", skipped {', '.join(skipped)}" if skipped else "")
    )
    strips = result.metrics.get("strips")
    if strips:
        print(
            f"[report] {len(strips['drawn'])} strip(s) of where a biased value's episodes part"
            + (f"; not drawn: {'; '.join(strips['skipped'])}" if strips["skipped"] else "")
        )


def main(args: list[str] | None = None) -> ReportResult:
    return cli_main(ReportConfig, run, _summary, (FileNotFoundError, EpisodesError), args)


if __name__ == "__main__":
    main()
