"""Turn evaluation episodes into metrics.json, report.md, report.html and plots.

    python -m pipelines.report --results=outputs/eval/episodes.parquet --output_dir=outputs/report

`--results` takes one parquet file or several, comma-separated (say one per policy); a file may
also hold several policies. Metrics follow docs/formats.md, "Metrics" (eval.metrics); for several
policies metrics.json holds {"epsilon", "resampling", "sources", "policies": {name: metrics}}.
Inputs are checked before any work: missing files or columns, repeated episodes and mixed
benchmark versions stop the run with a message naming the offender.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from eval.metrics import EPSILON, EpisodesError, MetricsConfig
from eval.report import HTML_FILE, REPORT_FILE, ReportResult, load_results, write_report
from pipelines._cli import cli_main


@dataclass
class ReportConfig:
    # Episode table(s) written by pipelines.evaluate: one path or several, comma-separated; NAME=PATH
    # names the file's policy in the report (e.g. act_ref=A.parquet,act_campose=B.parquet).
    results: str = ""
    # Folder that receives metrics.json, report.md, report.html (one self-contained page) and the PNG plots.
    output_dir: str = "outputs/report"
    # ε added to the mean in the CV and IEC denominators.
    epsilon: float = EPSILON
    # Within-(context, repeat) permutations behind cv_null and p_value_cv.
    n_perm: int = 1000
    # GLM calibration draws: permutations for sparse p_value, additive-model tables for iec_null.
    n_glm: int = 200
    # Seed of the bootstrap and permutation generators.
    seed: int = 0
    # Most permutations behind p_value_cv: more than n_perm are drawn while fewer than 20 reach the observed
    # CV (Besag–Clifford sequential p-value), so a strong bias resolves down to 1 / (max_perm + 1).
    max_perm: int = 20_000
    # Draw the PNG plots (false: metrics.json and report.md only).
    plots: bool = True

    def __post_init__(self) -> None:
        if not self.result_paths:
            raise ValueError("--results is required: the episodes.parquet file(s) of pipelines.evaluate")
        self.metrics_config  # validates epsilon, n_perm, n_glm and seed with their own messages

    @property
    def result_entries(self) -> list[tuple[str | None, Path]]:
        """(name or None, path) per entry; NAME=PATH renames the file's policy."""
        entries = []
        for item in filter(None, (x.strip() for x in self.results.split(","))):
            name, sep, path = item.partition("=")
            entries.append((name.strip(), Path(path.strip())) if sep and "/" not in name else (None, Path(item)))
        return entries

    @property
    def result_paths(self) -> list[Path]:
        return [path for _, path in self.result_entries]

    @property
    def metrics_config(self) -> MetricsConfig:
        try:
            return MetricsConfig(self.epsilon, self.n_perm, self.n_glm, self.seed, self.max_perm)
        except ValueError as exc:
            raise ValueError(f"--{exc}") from None


def run(cfg: ReportConfig) -> ReportResult:
    episodes, sources = load_results(cfg.result_paths, [name for name, _ in cfg.result_entries])
    return write_report(episodes, cfg.output_dir, cfg.metrics_config, sources=sources, plots=cfg.plots)


def _summary(cfg: ReportConfig, result: ReportResult) -> None:
    skipped = [name for name, reason in result.plots.items() if reason is not None]
    print(f"[report] {result.output_dir / REPORT_FILE} and {HTML_FILE}: {len(result.plots) - len(skipped)} plot(s) written"
          + (f", skipped {', '.join(skipped)}" if skipped else ""))


def main(args: list[str] | None = None) -> ReportResult:
    return cli_main(ReportConfig, run, _summary, (FileNotFoundError, EpisodesError), args)


if __name__ == "__main__":
    main()
