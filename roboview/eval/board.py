"""A leaderboard from result bundles: each fetched (a folder, or a Hub dataset downloaded), verified against the
board's benchmark exactly as roboview-verify does (a bundle that fails, or holds results of another benchmark or
version, is listed apart with the reason), the ranked bundles' episodes measured together, a report written for
each, and the board written by roboview.eval.reporting.leaderboard."""

from __future__ import annotations

import copy
import datetime
import json
from dataclasses import dataclass
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


@dataclass
class Checked:
    """A bundle that verified: its folder, the protocol it claims, its coverage and its replay."""

    path: Path
    policy: str
    protocol: str
    partial: bool
    covered: list[str]
    replayed: bool
    replay_note: str


def check_bundle(path: Path, benchmark: Path, version: str, replay: int = 0, loaded=None) -> Checked | str:
    """The bundle at `path` verified against the board's `benchmark` (version `version`), `replay` episodes drawn
    at random and re-run where its policy is reachable here; or why it cannot be ranked (one line: any file that
    cannot be read, any failed check)."""
    from roboview.eval.running.inputs import results_folder_problem
    from roboview.eval.running.results import PARQUET, read_version
    from roboview.eval.verification import verify_results

    if problem := results_folder_problem(path):
        return problem
    try:
        recorded = read_version(path / PARQUET)
        if recorded != version:
            return f"results of benchmark {recorded}; this board ranks {version}"
        result = verify_results(path, benchmark, replay, loaded=loaded)
        policy = bundle_policy(path)
    except Exception as exc:  # an unreadable or malformed bundle is listed apart, the board goes on
        return f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    unreachable = [c for c in result.checks if c.name == "replay" and "cannot rebuild policy" in c.detail]
    failed = [f"{c.name}: {c.detail}" for c in result.checks if not c.passed and c not in unreachable]
    if failed:
        return "verification failed — " + "; ".join(failed)
    if not result.coverage.get("protocol"):
        return "claims no protocol of the benchmark (evaluate with --eval.protocol=NAME to be ranked)"
    replay_note = (
        f"not replayed: {unreachable[0].detail}"
        if unreachable
        else next(
            (c.detail for c in result.checks if c.name == "replay"),
            "not replayed: the board ran with --replay=0",
        )
    )
    return Checked(
        path,
        policy,
        result.coverage["protocol"],
        bool(result.coverage["partial"]),
        list(result.coverage["covered"]),
        result.replay is not None and not unreachable,
        replay_note,
    )


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
    sources: list[str], benchmark: str = "", cache_dir: str | None = None, protocol: str = "", replay: int = 0
) -> tuple[str, str, dict[str, Checked], list[Rejected]]:
    """(benchmark version, the protocol ranked, the bundles that verify under it by source, those listed apart with
    the reason): every source fetched and checked against the board's benchmark (`benchmark`, else the one the
    bundles name). The board ranks one protocol: `protocol`, else the one most verified bundles claim."""
    from roboview.benchmark.format import load_benchmark

    rejected: list[Rejected] = []
    local: dict[str, Path] = {}
    for source in sources:
        try:
            local[source] = fetch(source, cache_dir)
        except RuntimeError as exc:
            rejected.append(Rejected(source, str(exc)))
    root = board_benchmark(benchmark, local)
    bench = load_benchmark(root)  # loaded and checked once; every bundle is verified against it
    verified: dict[str, Checked] = {}
    for source, path in local.items():
        checked = check_bundle(path, root, bench.version, replay, bench)
        if isinstance(checked, str):
            rejected.append(Rejected(source, checked))
        else:
            verified[source] = checked
    claims = [c.protocol for c in verified.values()]
    ranked = protocol or (max(dict.fromkeys(claims), key=claims.count) if claims else "")
    accepted = {s: c for s, c in verified.items() if c.protocol == ranked}
    rejected += [
        Rejected(s, f"claims protocol {c.protocol}; this board ranks protocol {ranked}")
        for s, c in verified.items()
        if c.protocol != ranked
    ]
    return bench.version, ranked, accepted, rejected


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
    protocol: str = "",
    replay: int = 0,
) -> Board:
    """Rank the bundles that verify under the board's protocol (the others listed apart) and write leaderboard.html,
    leaderboard.json and a report.html per ranked bundle under `output_dir`/reports/."""
    version, ranked, accepted, rejected = sort_bundles(sources, benchmark, cache_dir, protocol, replay)
    out = Path(output_dir)
    board = Board(
        version,
        [],
        rejected,
        generated=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        protocol=ranked,
    )
    if accepted:
        _rank(board, accepted, out, metrics, plots)
    write_board(board, out)
    return board


def _rank(
    board: Board, accepted: dict[str, Checked], out: Path, metrics_cfg: MetricsConfig, plots: bool
) -> None:
    """Measure the accepted bundles together: the board's entries (a report each) and its ranked rows (partial
    bundles per split only; the privileged ones as a reference line)."""
    from roboview.eval.reporting.leaderboard import rank_metrics
    from roboview.eval.reporting.report import HTML_FILE, load_results, write_report
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.statistics.metrics import compute_all_metrics

    labels = labels_for([c.policy for c in accepted.values()], list(accepted))
    episodes, sources = load_results([c.path / PARQUET for c in accepted.values()], labels)
    metrics = compute_all_metrics(episodes, metrics_cfg)
    several = "policies" in metrics
    for label, (source, checked), src in zip(labels, accepted.items(), sources):
        own = episodes[episodes["policy"] == label]
        report_dir = out / "reports" / label.replace("/", "_")
        # The bundle's own metrics are those just computed for it among the others: not computed again.
        mine = copy.deepcopy(metrics["policies"][label] if several else metrics)
        write_report(own, report_dir, metrics_cfg, sources=[src], plots=plots, metrics=mine)
        board.entries.append(
            Entry(
                label,
                source,
                checked.policy,
                str((report_dir / HTML_FILE).relative_to(out)),
                int((counted(own)).shape[0]),
                is_privileged_run(json.loads((checked.path / RUN_FILE).read_text())),
                checked.protocol,
                checked.partial,
                checked.replayed,
                checked.replay_note,
            )
        )
    layouts = metrics["policies"] if several else {labels[0]: metrics}
    board.overall, board.splits = rank_metrics(
        layouts,
        metrics.get("comparisons", []),
        episodes,
        partial={e.label for e in board.entries if e.partial},
        reference={e.label for e in board.entries if e.privileged},
    )
    board.resampling = metrics["resampling"]
