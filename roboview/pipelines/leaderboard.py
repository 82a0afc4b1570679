"""Rank policies from verified result bundles: one static leaderboard.html and leaderboard.json.

    roboview-leaderboard --results=outputs/eval/expert,outputs/eval/vision --output_dir=outputs/board
    roboview-leaderboard --results=ORG/vision-results,ORG/act-results --benchmark.path=DIR ...

`--results` names bundles: results folders (roboview.pipelines.evaluate's --output_dir, a merge of shards, or a bundle
`roboview.pipelines.publish --results` wrote) or Hub dataset ids of published bundles (downloaded with
huggingface_hub; `hf://datasets/ORG/NAME` or ORG/NAME when no such folder exists here). Every bundle is verified
against the board's benchmark (`--benchmark.path`; default: the one the first bundle's provenance names) exactly
as `roboview.pipelines.verify --results` does; a bundle that fails, or that holds results of another benchmark or
version, is listed apart with the reason and never ranked. The ranked bundles' episodes are measured together
(the statistics of `roboview.pipelines.report`): per split and overall, success rate and cv_excess with their 95 %
intervals, episodes, and significance groups (compact letters from Holm-adjusted paired tests: policies that
share a letter are not significantly different). Each row links to a report.html written for its bundle under
`reports/`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.board import build_board
from roboview.eval.reporting.leaderboard import BOARD_HTML, Board
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class LeaderboardConfig:
    # Result bundles, comma-separated: results folders, or Hub dataset ids of bundles roboview.pipelines.publish
    # --results uploaded (hf://datasets/ORG/NAME, or ORG/NAME when no such folder exists here).
    results: str = ""
    # Folder that receives leaderboard.html, leaderboard.json and reports/<policy>/report.html.
    output_dir: str = "outputs/leaderboard"
    # The board's benchmark; every bundle is verified against it (default: the benchmark the first bundle's
    # provenance names).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # How the statistics are computed (docs/statistics.md): --metrics.n_perm, --metrics.seed, ...
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    # Folder for Hub downloads (default: huggingface_hub's cache).
    cache_dir: str | None = None
    # Draw the plots of each bundle's report (false: the reports hold tables only, faster).
    plots: bool = True
    # The benchmark protocol the board ranks (every ranked bundle claims it; the others are listed apart). Empty:
    # the one most verified bundles claim.
    protocol: str = ""
    # Episodes of each bundle re-run here, drawn at random (0: none; a bundle whose policy cannot be rebuilt here is
    # marked "not replayed" with the reason, one whose replay disagrees is listed apart).
    replay: int = 0

    def __post_init__(self) -> None:
        if not self.sources:
            raise ValueError(
                "--results is required: result bundles (folders or Hub dataset ids), comma-separated"
            )
        if self.replay < 0:
            raise ValueError(f"--replay={self.replay} must be 0 or more")
        if len(set(self.sources)) != len(self.sources):
            raise ValueError(f"--results names a bundle twice: {self.results}")
        if self.benchmark.path:
            from roboview.eval.running.inputs import benchmark_folder_problem

            if problem := benchmark_folder_problem(Path(self.benchmark.path)):
                raise ValueError(f"--benchmark.path: {problem}")

    @property
    def sources(self) -> list[str]:
        return [s.strip() for s in self.results.split(",") if s.strip()]


def run(cfg: LeaderboardConfig) -> Board:
    return build_board(
        cfg.sources,
        cfg.output_dir,
        cfg.metrics,
        cfg.benchmark.path,
        cfg.cache_dir,
        cfg.plots,
        cfg.protocol,
        cfg.replay,
    )


def _summary(cfg: LeaderboardConfig, board: Board) -> None:
    for row in board.overall.get("sr", []):
        rank = "ref" if row["rank"] is None else f"{row['rank']:>2}."
        print(f"  {rank:>3} {row['policy']:<30} SR {100 * row['value']:6.2f}  group {row['group']}")
    for r in board.rejected:
        print(f"  listed apart: {r.source}: {r.reason}")
    print(
        f"[leaderboard] {Path(cfg.output_dir) / BOARD_HTML}: {len(board.entries)} ranked, "
        f"{len(board.rejected)} listed apart (benchmark {board.benchmark_version}, protocol {board.protocol or 'none'})"
    )


def main(args: list[str] | None = None) -> Board:
    from roboview.eval.running.results import ResultsError

    return cli_main(LeaderboardConfig, run, _summary, (ValueError, EpisodesError, ResultsError), args)


if __name__ == "__main__":
    main()
