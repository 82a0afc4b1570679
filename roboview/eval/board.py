"""A leaderboard from result bundles: each fetched (a folder, or a Hub dataset downloaded), verified against the
board's benchmark exactly as roboview-verify does (a bundle that fails, or holds results of another benchmark or
version, is listed apart with the reason), the ranked bundles' episodes measured together, a report written for
each, and the board written by roboview.eval.reporting.leaderboard."""

from __future__ import annotations

import copy
import datetime
import json
from pathlib import Path

from roboview.eval.reporting.leaderboard import Board, Entry, Rejected, labels_for, write_board
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig

HUB_PREFIX = "hf://datasets/"


def is_hub_id(source: str) -> bool:
    """Whether `source` names a Hub dataset (hf://datasets/ORG/NAME, or ORG/NAME when no such folder exists)."""
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


def board_benchmark(benchmark: str, local: dict[str, Path]) -> Path:
    """The board's benchmark folder: `benchmark`, else the last one a bundle's provenance names that exists here."""
    from roboview.eval.running import provenance

    if benchmark:
        return Path(benchmark)
    for path in local.values():
        recorded = [e.get("benchmark_path") for e in provenance.read(path) if e.get("benchmark_path")]
        if recorded and Path(recorded[-1]).is_dir():
            return Path(recorded[-1])
    raise ValueError(
        "no bundle names a benchmark folder that exists here; pass --benchmark.path=DIR (the benchmark the "
        "board ranks)"
    )


def sort_bundles(
    sources: list[str], benchmark: str = "", cache_dir: str | None = None
) -> tuple[str, dict[str, Path], list[Rejected]]:
    """(benchmark version, the bundles that verify by source, those listed apart with the reason): every source
    fetched and checked against the board's benchmark (`benchmark`, else the one the bundles name)."""
    from roboview.benchmark.format import load_benchmark

    rejected: list[Rejected] = []
    local: dict[str, Path] = {}
    for source in sources:
        try:
            local[source] = fetch(source, cache_dir)
        except RuntimeError as exc:
            rejected.append(Rejected(source, str(exc)))
    root = board_benchmark(benchmark, local)
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


def build_board(
    sources: list[str],
    output_dir: str | Path,
    metrics: MetricsConfig,
    benchmark: str = "",
    cache_dir: str | None = None,
    plots: bool = True,
) -> Board:
    """Rank the bundles that verify (the others listed apart) and write leaderboard.html, leaderboard.json and a
    report.html per ranked bundle under `output_dir`/reports/."""
    version, accepted, rejected = sort_bundles(sources, benchmark, cache_dir)
    out = Path(output_dir)
    board = Board(
        version, [], rejected, generated=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    )
    if accepted:
        _rank(board, accepted, out, metrics, plots)
    write_board(board, out)
    return board


def _rank(
    board: Board, accepted: dict[str, Path], out: Path, metrics_cfg: MetricsConfig, plots: bool
) -> None:
    """Measure the accepted bundles together: the board's entries (a report each) and its ranked rows."""
    from roboview.eval.reporting.leaderboard import rank_metrics, single_policy_rows
    from roboview.eval.reporting.report import HTML_FILE, load_results, write_report
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.statistics.metrics import compute_all_metrics

    # Each bundle's policy, read first: the labels rename them when loaded.
    policies = [bundle_policy(path) for path in accepted.values()]
    labels = labels_for(policies, list(accepted))
    episodes, sources = load_results([p / PARQUET for p in accepted.values()], labels)
    metrics = compute_all_metrics(episodes, metrics_cfg)
    several = "policies" in metrics
    for label, policy, (source, path), src in zip(labels, policies, accepted.items(), sources):
        own = episodes[episodes["policy"] == label]
        report_dir = out / "reports" / label.replace("/", "_")
        # The bundle's own metrics are those just computed for it among the others: not computed again.
        mine = copy.deepcopy(metrics["policies"][label] if several else metrics)
        write_report(own, report_dir, metrics_cfg, sources=[src], plots=plots, metrics=mine)
        board.entries.append(
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
