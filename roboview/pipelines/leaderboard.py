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

import copy
import datetime
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.reporting.leaderboard import (
    BOARD_HTML,
    Board,
    Entry,
    Rejected,
    labels_for,
    write_board,
)
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig
from roboview.pipelines._cli import BenchmarkPath, cli_main

log = logging.getLogger(__name__)

HUB_PREFIX = "hf://datasets/"


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

    def __post_init__(self) -> None:
        if not self.sources:
            raise ValueError(
                "--results is required: result bundles (folders or Hub dataset ids), comma-separated"
            )
        if len(set(self.sources)) != len(self.sources):
            raise ValueError(f"--results names a bundle twice: {self.results}")
        if self.benchmark.path:
            from roboview.eval.running.inputs import benchmark_folder_problem

            if problem := benchmark_folder_problem(Path(self.benchmark.path)):
                raise ValueError(f"--benchmark.path: {problem}")

    @property
    def sources(self) -> list[str]:
        return [s.strip() for s in self.results.split(",") if s.strip()]


def is_hub_id(source: str) -> bool:
    if source.startswith(HUB_PREFIX):
        return True
    parts = source.split("/")
    return len(parts) == 2 and all(parts) and not Path(source).exists() and not source.startswith(".")


def fetch(source: str, cache_dir: str | None = None) -> Path:
    """A local folder for `source`: the folder itself, or the Hub dataset downloaded (RuntimeError saying why
    not: offline, not found, no access)."""
    if not is_hub_id(source):
        return Path(source)
    from huggingface_hub import snapshot_download

    repo_id = source.removeprefix(HUB_PREFIX)
    try:
        return Path(snapshot_download(repo_id, repo_type="dataset", cache_dir=cache_dir))
    except Exception as exc:  # offline, missing repo, refused token: the bundle is listed apart
        raise RuntimeError(f"cannot download Hub dataset {repo_id}: {type(exc).__name__}: {exc}") from exc


def check_bundle(path: Path, benchmark: Path, version: str) -> str | None:
    """Why the bundle at `path` cannot be ranked on the board of `benchmark` (version `version`); None: it can."""
    from roboview.eval.running.inputs import results_folder_problem
    from roboview.eval.running.results import PARQUET, read_version
    from roboview.eval.verification import verify_results

    if problem := results_folder_problem(path):
        return problem
    recorded = read_version(path / PARQUET)
    if recorded != version:
        return f"results of benchmark {recorded}; this board ranks {version}"
    result = verify_results(path, benchmark)
    failed = [f"{c.name}: {c.detail}" for c in result.checks if not c.passed]
    return "verification failed — " + "; ".join(failed) if failed else None


def _board_benchmark(cfg: LeaderboardConfig, local: dict[str, Path]) -> Path:
    from roboview.eval.running import provenance

    if cfg.benchmark.path:
        return Path(cfg.benchmark.path)
    for path in local.values():
        recorded = [e.get("benchmark_path") for e in provenance.read(path) if e.get("benchmark_path")]
        if recorded and Path(recorded[-1]).is_dir():
            return Path(recorded[-1])
    raise ValueError(
        "no bundle names a benchmark folder that exists here; pass --benchmark.path=DIR (the benchmark the "
        "board ranks)"
    )


def sort_bundles(cfg: LeaderboardConfig) -> tuple[str, dict[str, Path], list[Rejected]]:
    """(benchmark version, the bundles that verify by source, those listed apart with the reason): every source
    fetched and checked against the board's benchmark."""
    from roboview.benchmark.format import load_benchmark

    rejected: list[Rejected] = []
    local: dict[str, Path] = {}
    for source in cfg.sources:
        try:
            local[source] = fetch(source, cfg.cache_dir)
        except RuntimeError as exc:
            rejected.append(Rejected(source, str(exc)))
    root = _board_benchmark(cfg, local)
    version = load_benchmark(root).version
    accepted: dict[str, Path] = {}
    for source, path in local.items():
        reason = check_bundle(path, root, version)
        if reason:
            rejected.append(Rejected(source, reason))
        else:
            accepted[source] = path
    return version, accepted, rejected


def bundle_policy(path: Path) -> str:
    """The one policy a bundle's counted episodes name; EpisodesError for a bundle of several."""
    import pandas as pd
    import pyarrow.parquet as pq

    from roboview.eval.running.results import PARQUET, STATUS, counted

    columns = [c for c in ("policy", STATUS) if c in pq.read_schema(path / PARQUET).names]
    names = sorted(map(str, counted(pd.read_parquet(path / PARQUET, columns=columns))["policy"].unique()))
    if len(names) != 1:
        raise EpisodesError(f"{path} holds several policies ({', '.join(names)}); give one per bundle")
    return names[0]


def run(cfg: LeaderboardConfig) -> Board:
    from roboview.eval.reporting.leaderboard import rank_metrics, single_policy_rows
    from roboview.eval.reporting.report import HTML_FILE, load_results, write_report
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.statistics.metrics import compute_all_metrics

    version, accepted, rejected = sort_bundles(cfg)
    out = Path(cfg.output_dir)
    entries: list[Entry] = []
    board = Board(
        version,
        entries,
        rejected,
        generated=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    )
    if accepted:
        # Each bundle's policy, read first: the labels rename them when loaded.
        policies = [bundle_policy(path) for path in accepted.values()]
        labels = labels_for(policies, list(accepted))
        episodes, sources = load_results([p / PARQUET for p in accepted.values()], labels)
        metrics = compute_all_metrics(episodes, cfg.metrics)
        several = "policies" in metrics
        for label, policy, (source, path), src in zip(labels, policies, accepted.items(), sources):
            own = episodes[episodes["policy"] == label]
            report_dir = out / "reports" / label.replace("/", "_")
            # The bundle's own metrics are those just computed for it among the others: not computed again.
            mine = copy.deepcopy(metrics["policies"][label] if several else metrics)
            write_report(own, report_dir, cfg.metrics, sources=[src], plots=cfg.plots, metrics=mine)
            entries.append(
                Entry(
                    label,
                    source,
                    policy,
                    str((report_dir / HTML_FILE).relative_to(out)),
                    int((counted(own)).shape[0]),
                    is_privileged_run(json.loads((path / RUN_FILE).read_text())),
                )
            )
        if several:
            board.overall, board.splits = rank_metrics(metrics, episodes)
        else:
            board.overall, board.splits = single_policy_rows(metrics)
        board.resampling = metrics["resampling"]
    write_board(board, out)
    return board


def _summary(cfg: LeaderboardConfig, board: Board) -> None:
    for row in board.overall.get("sr", []):
        print(f"  {row['rank']:>2}. {row['policy']:<30} SR {100 * row['value']:6.2f}  group {row['group']}")
    for r in board.rejected:
        print(f"  listed apart: {r.source}: {r.reason}")
    print(
        f"[leaderboard] {Path(cfg.output_dir) / BOARD_HTML}: {len(board.entries)} ranked, "
        f"{len(board.rejected)} listed apart (benchmark {board.benchmark_version})"
    )


def main(args: list[str] | None = None) -> Board:
    from roboview.eval.running.results import ResultsError

    return cli_main(LeaderboardConfig, run, _summary, (ValueError, EpisodesError, ResultsError), args)


if __name__ == "__main__":
    main()
