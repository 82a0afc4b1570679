"""A leaderboard from result bundles: each fetched (a folder, or a Hub dataset downloaded), verified against the
board's benchmark exactly as roboview-verify does, and a sample of its episodes drawn at random and re-run here (5 %
at 95 % by default). Two tables, never mixed: the bundles whose replay passed are measured together and ranked; those
whose episodes cannot be re-run here (an unreachable or stochastic policy, another simulation stack) are claims,
each measured alone; a bundle that fails a check, whose replay disagrees with its rows, or that holds results of
another benchmark or version is rejected with the reason. The board is written by roboview.eval.reporting.leaderboard."""

from __future__ import annotations

import copy
import datetime
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

from roboview.eval.reporting.leaderboard import Board, Claim, Entry, Rejected, labels_for
from roboview.eval.reporting.leaderboard_page import write_board
from roboview.eval.statistics.metrics import EpisodesError, MetricsConfig
from roboview.sim.stack import summary

log = logging.getLogger(__name__)

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
    """A bundle that verified: its folder, the protocol it claims, its coverage and its replay; `claim`: why its
    outcomes could not be re-run here ("" when they were, or when the board replays nothing)."""

    path: Path
    policy: str
    protocol: str
    partial: bool
    covered: list[str]
    replayed: bool
    replay_note: str
    claim: str = ""


@dataclass(frozen=True)
class Replay:
    """How the board replays each bundle: `n` episodes drawn at random here (0: none), the guarantee stated for a
    forgery of `detect` of a bundle's rows."""

    n: int
    detect: float = 0.05

    @property
    def confidence(self) -> float:
        """The probability that a forgery of `detect` of the rows is caught by the n episodes (at least)."""
        return 1 - (1 - self.detect) ** self.n

    def words(self) -> str:
        if not self.n:
            return "nothing replayed (--replay=0): every bundle's outcomes are taken as it reports them"
        return (
            f"{self.n} episodes of each bundle (all, where it has fewer) drawn at random and re-run here: a forgery "
            f"of ≥ {self.detect:.0%} of a bundle's rows is caught with probability ≥ {self.confidence:.1%}"
        )

    def record(self) -> dict:
        return {
            "n": self.n,
            "detect": self.detect,
            "confidence": round(self.confidence, 4),
            "guarantee": self.words(),
        }


def check_bundle(
    path: Path,
    benchmark: Path,
    version: str,
    replay: Replay = Replay(0),
    loaded=None,
    replayer=None,
    stack: dict | None = None,
) -> Checked | str:
    """The bundle at `path` verified against the board's `benchmark` (version `version`) and, with `replay.n`, a
    sample re-run here with `replayer` when it ran on this machine's simulation `stack`; or why it cannot be listed
    (one line: any file that cannot be read, any failed check, a replay that disagrees with reproducible rows)."""
    from roboview.eval.running.inputs import results_folder_problem
    from roboview.eval.running.results import PARQUET, read_version
    from roboview.eval.verification import verify_results

    if problem := results_folder_problem(path):
        return problem
    try:
        recorded = read_version(path / PARQUET)
        if recorded != version:
            return f"results of benchmark {recorded}; this board ranks {version}"
        other = other_stack(path, stack) if replay.n else ""
        n = 0 if other else replay.n
        result = verify_results(path, benchmark, n, replay.detect, loaded=loaded, replayer=replayer)
        policy = bundle_policy(path)
    except Exception as exc:  # an unreadable or malformed bundle is listed apart, the board goes on
        return f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    replayed = next((c for c in result.checks if c.name == "replay"), None)
    failed = [f"{c.name}: {c.detail}" for c in result.checks if not c.passed and c is not replayed]
    if failed:
        return "verification failed — " + "; ".join(failed)
    if not result.coverage.get("protocol"):
        return "claims no protocol of the benchmark (evaluate with --eval.protocol=NAME to be ranked)"
    record = result.replay or {}
    if not replay.n:
        claim, note = "", "not replayed: the board ran with --replay=0"
    elif other:
        claim = note = f"another stack: {other}"
    elif replayed.passed:
        claim, note = "", replayed.detail
    elif "error" in record:
        claim = note = f"unreachable: {replayed.detail}"
    elif not record.get("reproducible", True):
        claim = note = f"stochastic: {replayed.detail}"
    else:
        return f"verification failed — replay: {replayed.detail}"
    coverage = result.coverage
    return Checked(
        path,
        policy,
        coverage["protocol"],
        bool(coverage["partial"]),
        list(coverage["covered"]),
        bool(replay.n) and not claim,
        note,
        claim,
    )


def other_stack(path: Path, stack: dict | None) -> str:
    """How the simulation stacks the bundle's runs recorded differ from `stack` (this machine's), in one line; ""
    when every run's is the same (its episodes can be re-run here as they ran)."""
    from roboview.eval.running import provenance
    from roboview.sim.stack import differences, summary

    recorded = [
        e["conformance"]["stack"] for e in provenance.read(path) if (e.get("conformance") or {}).get("stack")
    ]
    for theirs in recorded:
        if diffs := differences(theirs, stack):
            return f"it ran on {summary(theirs)}, this board runs {summary(stack)} ({'; '.join(diffs)})"
    return ""


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


@dataclass
class Sorted:
    """The bundles of a board, sorted: its benchmark version and protocol, those ranked (replay passed, or the board
    replays nothing), the claims (verified, but not re-run here) and those rejected, with the replay's record."""

    version: str
    protocol: str
    accepted: dict[str, Checked]
    claims: dict[str, Checked]
    rejected: list[Rejected]
    replay: dict


def sort_bundles(
    sources: list[str],
    benchmark: str = "",
    cache_dir: str | None = None,
    protocol: str = "",
    replay: Replay = Replay(0),
) -> Sorted:
    """Every source fetched and checked against the board's benchmark (`benchmark`, else the one the bundles name),
    `replay.n` episodes of each re-run here. The board ranks one protocol: `protocol`, else the one most verified
    bundles claim."""
    from roboview.benchmark.format import load_benchmark
    from roboview.eval.verification.replay import Replayer

    rejected: list[Rejected] = []
    local: dict[str, Path] = {}
    for source in sources:
        try:
            local[source] = fetch(source, cache_dir)
        except RuntimeError as exc:
            rejected.append(Rejected(source, str(exc)))
    root = board_benchmark(benchmark, local)
    bench = load_benchmark(root)  # loaded and checked once; every bundle is verified against it
    stack = board_stack(root, bench.version) if replay.n else None
    verified: dict[str, Checked] = {}
    start = time.perf_counter()
    replayer = Replayer()
    try:
        for source, path in local.items():
            checked = check_bundle(path, root, bench.version, replay, bench, replayer, stack)
            if isinstance(checked, str):
                rejected.append(Rejected(source, checked))
            else:
                verified[source] = checked
            log.info("%s: %s", source, checked if isinstance(checked, str) else checked.replay_note)
    finally:
        replayer.close()
    claimed = [c.protocol for c in verified.values()]
    ranked = protocol or (max(dict.fromkeys(claimed), key=claimed.count) if claimed else "")
    rejected += [
        Rejected(s, f"claims protocol {c.protocol}; this board ranks protocol {ranked}")
        for s, c in verified.items()
        if c.protocol != ranked
    ]
    mine = {s: c for s, c in verified.items() if c.protocol == ranked}
    record = replay.record() | {
        "seconds": round(time.perf_counter() - start, 1),  # every bundle's checks and replay
        "stack": summary(stack) if stack else None,
    }
    return Sorted(
        bench.version,
        ranked,
        {s: c for s, c in mine.items() if not c.claim},
        {s: c for s, c in mine.items() if c.claim},
        rejected,
        record,
    )


def board_stack(root: Path, version: str) -> dict:
    """This machine's simulation stack, as an evaluation here records it (its conformance verdict is cached)."""
    from roboview.benchmark import conformance

    return conformance.at_start(root, version).stack


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
    replay: Replay = Replay(0),
) -> Board:
    """Rank the bundles whose replay passed under the board's protocol, list the claims (not re-run here) and the
    rejected apart, and write leaderboard.html, leaderboard.json and a report.html per bundle under
    `output_dir`/reports/."""
    bundles = sort_bundles(sources, benchmark, cache_dir, protocol, replay)
    out = Path(output_dir)
    board = Board(
        bundles.version,
        [],
        bundles.rejected,
        generated=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        protocol=bundles.protocol,
        replay=bundles.replay,
    )
    listed = {**bundles.accepted, **bundles.claims}
    labels = dict(zip(listed, labels_for([c.policy for c in listed.values()], list(listed))))
    if bundles.accepted:
        _rank(board, {s: (labels[s], c) for s, c in bundles.accepted.items()}, out, metrics, plots)
    for source, checked in bundles.claims.items():
        board.claims.append(_claim(labels[source], source, checked, out, metrics, plots))
    write_board(board, out)
    return board


def _claim(
    label: str, source: str, checked: Checked, out: Path, metrics_cfg: MetricsConfig, plots: bool
) -> Claim:
    """A claim measured alone (its own report; never pooled or tested with another bundle): what it claims overall,
    with its Clopper–Pearson interval."""
    from roboview.eval.reporting.report import HTML_FILE, load_results, write_report
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.statistics.tables import rate_ci95

    episodes, src = load_results([checked.path / PARQUET], [label])
    report_dir = out / "reports" / label.replace("/", "_")
    write_report(episodes, report_dir, metrics_cfg, sources=src, plots=plots)
    success = counted(episodes)["success"]
    k, n = int(success.sum()), int(success.shape[0])
    return Claim(
        label,
        source,
        checked.policy,
        str((report_dir / HTML_FILE).relative_to(out)),
        n,
        is_privileged_run(json.loads((checked.path / RUN_FILE).read_text())),
        checked.protocol,
        checked.partial,
        False,
        checked.replay_note,
        sr=k / n if n else None,
        sr_ci95=rate_ci95(k, n),
        covered=checked.covered,
    )


def _rank(
    board: Board, accepted: dict[str, tuple[str, Checked]], out: Path, metrics_cfg: MetricsConfig, plots: bool
) -> None:
    """Measure the accepted bundles together: the board's entries (a report each) and its ranked rows (partial
    bundles per split only; the privileged ones as a reference line)."""
    from roboview.eval.reporting.leaderboard import rank_metrics
    from roboview.eval.reporting.report import HTML_FILE, load_results, write_report
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.statistics.metrics import compute_all_metrics

    labels = [label for label, _ in accepted.values()]
    episodes, sources = load_results([c.path / PARQUET for _, c in accepted.values()], labels)
    metrics = compute_all_metrics(episodes, metrics_cfg)
    several = "policies" in metrics
    for (source, (label, checked)), src in zip(accepted.items(), sources):
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
