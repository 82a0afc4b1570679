"""Rank policies from verified result bundles: one static leaderboard.html and leaderboard.json.

    roboview-leaderboard --results=outputs/eval/expert,outputs/eval/vision --output_dir=outputs/board
    roboview-leaderboard --results=ORG/vision-results,ORG/act-results --benchmark.path=DIR ...

`--results` names bundles: results folders (roboview.pipelines.evaluate's --output_dir, a merge of shards, or a bundle
`roboview.pipelines.publish --results` wrote) or Hub dataset ids of published bundles (downloaded with
huggingface_hub; `hf://datasets/ORG/NAME` or ORG/NAME when no such folder exists here). Every bundle is verified
against the board's benchmark (`--benchmark.path`; default: the one the first bundle's provenance names) exactly
as `roboview.pipelines.verify --results` does, and a sample of its episodes drawn at random is re-run here, sized as
`roboview-verify --replay.detect=0.05 --replay.confidence=0.95` sizes it (59 episodes; the guarantee is printed and
recorded in leaderboard.json). Only bundles whose replay passed are ranked. A bundle whose episodes cannot be re-run
here (its policy unreachable or not reproducible from the episode seed, or run on another simulation stack) is a
claim: listed apart with the reason, measured alone, never ranked or compared. A bundle that fails a check, whose
replay disagrees with its rows, or that holds results of another benchmark or version is rejected with the reason.
`--replay=0` re-runs nothing: the page's title then says so and no row is called verified. The ranked bundles'
episodes are measured together
(the statistics of `roboview.pipelines.report`): per split and overall, success rate and cv_excess with their 95 %
intervals, episodes, and significance groups (compact letters from Holm-adjusted paired tests: policies that
share a letter are not significantly different). Each row links to a report.html written for its bundle under
`reports/`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.campaign.board import Replay, build_board
from roboview.eval.reporting.leaderboard import BOARD_HTML, Board
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig
from roboview.pipelines._cli import BenchmarkPath, ReplayConfig, cli_main, replay_flag


@dataclass
class BoardReplayConfig(ReplayConfig):
    """The board's replay: the guarantee roboview-verify states, 5 % at 95 %, unless told otherwise."""

    # Size each bundle's sample to catch any forgery of at least this share of its rows (0: no replay) ...
    detect: float = 0.05


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
    # Episodes of each bundle re-run here, drawn at random: by default as many as catch a forgery of ≥ 5 % of its
    # rows with probability ≥ 95 % (--replay.detect, --replay.confidence); --replay=N fixes N, --replay=0 re-runs
    # none (the page then says so in its title). Only bundles whose replay passed are ranked; one whose episodes
    # cannot be re-run here is a claim, listed apart; one whose replay disagrees is rejected.
    replay: BoardReplayConfig = field(default_factory=BoardReplayConfig)

    def __post_init__(self) -> None:
        if not self.sources:
            raise ValueError(
                "--results is required: result bundles (folders or Hub dataset ids), comma-separated"
            )
        self.replay.size()  # a bad n, detect or confidence fails here
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
    replay = Replay(cfg.replay.size(), cfg.replay.detect or 0.05)
    print(f"[leaderboard] replay: {replay.words()}", flush=True)
    return build_board(
        cfg.sources,
        cfg.output_dir,
        cfg.metrics,
        cfg.benchmark.path,
        cfg.cache_dir,
        cfg.plots,
        cfg.protocol,
        replay,
    )


def _summary(cfg: LeaderboardConfig, board: Board) -> None:
    for row in board.overall.get("sr", []):
        rank = "ref" if row["rank"] is None else f"{row['rank']:>2}."
        print(f"  {rank:>3} {row['policy']:<30} SR {100 * row['value']:6.2f}  group {row['group']}")
    for c in board.claims:
        sr = "—" if c.sr is None else f"{100 * c.sr:6.2f}"
        print(f"  claim (not ranked): {c.label} SR {sr}: {c.replay_note}")
    for r in board.rejected:
        print(f"  rejected: {r.source}: {r.reason}")
    replayed = (
        f"replayed in {board.replay['seconds']:.0f} s"
        if board.replayed
        else "NOT REPLAYED (--replay=0): no ranked row is verified"
    )
    print(
        f"[leaderboard] {Path(cfg.output_dir) / BOARD_HTML}: {len(board.entries)} ranked, {len(board.claims)} "
        f"claims listed apart, {len(board.rejected)} rejected ({replayed}; benchmark {board.benchmark_version}, "
        f"protocol {board.protocol or 'none'})"
    )


def main(args: list[str] | None = None) -> Board:
    import sys

    from roboview.eval.running.results import ResultsError

    argv = replay_flag(args if args is not None else sys.argv[1:])
    return cli_main(LeaderboardConfig, run, _summary, (ValueError, EpisodesError, ResultsError), argv)


if __name__ == "__main__":
    main()
