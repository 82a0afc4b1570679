"""A results folder against its benchmark: every row an instance of it with identical content and its
common-random-number seed, no (instance, repeat) twice, the isolation certificate, completeness for the run's
protocol (an adaptive split: its stopping record follows from its rows), no uncounted infrastructure error, every
row's conformance verdict, a published bundle's files against bundle.json, and optionally a replayed sample."""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq

from roboview.benchmark.format import read_manifest
from roboview.core.folders import folder_problem
from roboview.eval.reporting.bundle import BUNDLE_FILE, manifest_problems
from roboview.eval.running import provenance
from roboview.eval.running.results import PARQUET, recorded_threads
from roboview.eval.running.row import INFRA_ERROR, STATUS
from roboview.eval.statistics.adaptive import read_record
from roboview.eval.verification.integrity import (
    check_conformance,
    check_plausible,
    check_record,
    check_schema,
)
from roboview.eval.verification.report import Check, Report, listed


def benchmark_path(results: str | Path, benchmark: str | Path | None = None) -> Path:
    """The benchmark folder `results` are checked against: `benchmark` if given, else the one its provenance
    names."""
    results = Path(results)
    if benchmark:
        return Path(benchmark)
    recorded = [e.get("benchmark_path") for e in provenance.read(results) if e.get("benchmark_path")]
    if recorded and Path(recorded[-1]).is_dir():
        return Path(recorded[-1])
    raise ValueError(
        f"{results} does not name a benchmark folder that exists here "
        f"({recorded[-1] if recorded else 'none recorded'}); pass --benchmark.path=DIR"
    )


def read_rows(results: Path) -> tuple[list[dict], dict]:
    """The results' rows (as stored) and run.json; ResultsError for a folder that holds none."""
    table, run = read_table(results)
    return table.to_pylist(), run


def read_table(results: Path):
    """The results' episode table and run.json; ResultsError, one line naming the file and the problem, for a
    folder that holds none or a file that cannot be read."""
    from roboview.eval.running.results import PARQUET, RUN_FILE, ResultsError, check_format

    advice = "give the folder roboview-evaluate wrote (--output_dir)"
    problem = folder_problem(results, "results", RUN_FILE, advice) or folder_problem(
        results, "results", PARQUET, advice
    )
    if problem:
        raise ResultsError(problem)
    try:
        check_format(results / PARQUET)  # refuses other results formats with its own message
        table = pq.read_table(results / PARQUET)
    except ResultsError:
        raise
    except Exception as exc:  # a torn, zeroed or foreign file: named, never a traceback
        raise ResultsError(
            f"{results / PARQUET} cannot be read as a parquet table ({type(exc).__name__}: {exc})"
        ) from None
    try:
        run = json.loads((results / RUN_FILE).read_text())
    except (OSError, ValueError) as exc:
        raise ResultsError(
            f"{results / RUN_FILE} is not readable JSON ({type(exc).__name__}: {exc})"
        ) from None
    if not isinstance(run, dict):
        raise ResultsError(f"{results / RUN_FILE} holds a JSON {type(run).__name__}, not an object")
    threads = recorded_threads(results) if "torch_threads" not in run else None
    if threads:  # a folder written before run.json recorded them: its provenance's count
        run["torch_threads"] = threads
    return table, run


def check_rows(rows: list[dict], bench) -> list[Check]:
    """Instances, seeds and duplicates of the rows against the benchmark's records."""
    records = {i.record["instance_id"]: i.record for items in bench.splits.values() for i in items}
    # A benchmark read otherwise than it was written (format 4: LIBERO's `red` baseline read as `original`): rows an
    # earlier version evaluated carry the written record, and are its instances too.
    built = {
        i.record["instance_id"]: i.as_built for items in bench.splits.values() for i in items if i.as_built
    }
    checks = [check_instances(rows, records, built), check_seeds(rows, records), check_duplicates(rows)]
    return checks + [check_repeats(rows, bench)]


def check_instances(
    rows: list[dict], records: dict[str, dict], as_built: dict[str, dict] | None = None
) -> Check:
    """Every row an instance of the benchmark, its instance columns as the benchmark records them (or, where it
    reads a row otherwise than its build wrote it, as written: `as_built`)."""
    unknown = [r["instance_id"] for r in rows if r["instance_id"] not in records]
    edited = []
    for row in rows:
        record = records.get(row["instance_id"])
        cols = [c for c, v in record.items() if row.get(c) != v] if record is not None else []
        written = (as_built or {}).get(row["instance_id"])
        if cols and written is not None and all(row.get(c) == v for c, v in written.items()):
            cols = []
        if cols:
            edited.append(f"{row['instance_id']} repeat {row['repeat']} ({', '.join(cols)})")
    problems = [
        f"{len(unknown)} rows name instances the benchmark does not hold: {listed(sorted(set(unknown)))}"
        if unknown
        else "",
        f"{len(edited)} rows differ from their instance's record: {listed(edited)}" if edited else "",
    ]
    return Check(
        "instances",
        not unknown and not edited,
        "; ".join(filter(None, problems))
        or f"{len(rows)} rows, each an instance of the benchmark with identical content",
    )


def check_seeds(rows: list[dict], records: dict[str, dict]) -> Check:
    """Every episode seed the common-random-number seed of its (context, repeat)."""
    from roboview.variation.instances import episode_seed

    bad = []
    for r in rows:
        if r["instance_id"] in records:
            expected = episode_seed(records[r["instance_id"]]["context_id"], r["repeat"])
            if r.get("episode_seed") != expected:
                bad.append(
                    f"{r['instance_id']} repeat {r['repeat']} (seed {r.get('episode_seed')}, expected {expected})"
                )
    return Check(
        "seeds",
        not bad,
        f"{len(bad)} rows with another seed: {listed(bad)}"
        if bad
        else "every episode seed is its (context, repeat)'s common-random-number seed",
    )


def check_repeats(rows: list[dict], bench) -> Check:
    """Repeats are distinct episodes: on a world whose repeats advance a context factor (LIBERO's init state), every
    row records the value its repeat ran (`episode_unit`), the one the benchmark's rule gives. A folder of the
    seed-only design (repeats from the instance's own init state: copies) fails."""
    from roboview.tasks.repetition import UNIT_COLUMN

    items = {i.record["instance_id"]: i for items in bench.splits.values() for i in items}
    copies, wrong = [], []
    for r in rows:
        item = items.get(r["instance_id"])
        if item is None or not item.repetition.factor:
            continue
        expected = item.repetition.unit(item.instance, r["repeat"])
        if r.get(UNIT_COLUMN) is None and r["repeat"] > 0:
            copies.append(f"{r['instance_id']} repeat {r['repeat']}")
        elif r.get(UNIT_COLUMN) is not None and r[UNIT_COLUMN] != expected:
            wrong.append(f"{r['instance_id']} repeat {r['repeat']} ({r[UNIT_COLUMN]}, expected {expected})")
    problems = [
        f"{len(copies)} repeats are copies of their instance's repeat 0 (recorded without {UNIT_COLUMN}: every "
        f"repeat started from the instance's own init state; reports count each instance once; re-run for "
        f"distinct episodes): {listed(copies)}"
        if copies
        else "",
        f"{len(wrong)} rows ran another {UNIT_COLUMN} than their repeat's: {listed(wrong)}" if wrong else "",
    ]
    rules = {i.repetition.describe() for i in items.values() if i.repetition.factor}
    return Check(
        "repeats",
        not copies and not wrong,
        "; ".join(filter(None, problems))
        or (
            "every repeat a distinct episode: " + "; ".join(sorted(rules))
            if rules
            else "the seed makes each repeat"
        ),
    )


def check_duplicates(rows: list[dict]) -> Check:
    """No (instance, repeat) twice."""
    counts = Counter((r["instance_id"], r["repeat"]) for r in rows)
    twice = [f"{i} repeat {r} ×{n}" for (i, r), n in counts.items() if n > 1]
    return Check(
        "duplicates",
        not twice,
        f"{len(twice)} (instance, repeat) pairs appear more than once: {listed(twice)}"
        if twice
        else "no (instance, repeat) twice",
    )


def check_complete(rows: list[dict], bench, run: dict, results: Path) -> tuple[Check, dict]:
    """Coverage against the benchmark's protocol the run claims (never the run's own run.json): every covered
    split whole (all its instances × the protocol's repeats, or for an adaptive split the rounds its stopping record
    says, with the decision its rows give) and no row beyond the protocol. Returns the check and the coverage
    (`protocol`, `covered` splits, `partial`). A run that claims no protocol is checked against its own run.json
    and ranked nowhere."""
    claimed = run.get("protocol") or ""
    if not claimed:
        check = check_own_run(rows, bench, run, results)
        detail = (
            f"claims no protocol of the benchmark (it declares {', '.join(bench.protocols)}): {check.detail}"
        )
        return Check("complete", check.passed, detail), {"protocol": "", "covered": [], "partial": True}
    if claimed not in bench.protocols:
        detail = f"claims protocol {claimed!r}; the benchmark declares {', '.join(bench.protocols)}"
        return Check("complete", False, detail), {"protocol": claimed, "covered": [], "partial": True}
    protocol = bench.protocols[claimed]
    by_split: dict[str, list[dict]] = {}
    for row in rows:
        by_split.setdefault(row["split"], []).append(row)
    problems = [
        f"{len(extra)} rows of split {split}, which protocol {claimed} does not cover"
        for split, extra in by_split.items()
        if split not in protocol.splits
    ]
    record = (read_record(results) or {}) if protocol.adaptive is not None else {}
    covered = [s for s in protocol.splits if by_split.get(s)]
    for split in covered:
        problem = _split_problem(split, by_split[split], bench, protocol, record)
        if problem:
            problems.append(f"{split}: {problem}")
    partial = len(covered) < len(protocol.splits)
    if problems:
        detail = f"protocol {claimed}: " + "; ".join(problems)
    elif not covered:
        detail = f"protocol {claimed}: no split covered"
    else:
        detail = f"protocol {claimed}: {len(covered)} of {len(protocol.splits)} splits whole" + (
            f" (partial: {', '.join(s for s in protocol.splits if s not in covered)} not run; ranked per split only)"
            if partial
            else ""
        )
    coverage = {"protocol": claimed, "covered": covered, "partial": partial}
    return Check("complete", not problems and bool(covered), detail), coverage


def _split_problem(split: str, rows: list[dict], bench, protocol, record: dict) -> str:
    """What keeps a covered split from being whole under `protocol`: missing rows, rows beyond it, a stopping
    record its rows do not give; "" when it is whole."""
    from roboview.eval.statistics.adaptive import Design, decide_split

    ids = {i.record["instance_id"] for i in bench.splits.get(split, [])}
    if protocol.adaptive_split(split):
        stopped = record.get("splits", {}).get(split)
        design = Design(**protocol.adaptive)
        if stopped is None:
            return "adaptive under the protocol but no stopping record (unfinished: rerun the same command)"
        if record.get("design") and Design(**record["design"]) != design:
            return f"stopping record's design {record['design']} is not the protocol's {protocol.adaptive}"
        rounds = int(stopped["rounds"])
        if rounds > design.max_repeats:
            return f"{rounds} rounds, beyond the protocol's {design.max_repeats}"
    else:
        rounds, stopped = protocol.n_repeats[split], None
    have = {(r["instance_id"], int(r["repeat"])) for r in rows}
    want = {(i, r) for i in ids for r in range(rounds)}
    missing, beyond = sorted(want - have), sorted(have - want)
    if missing:
        return (
            f"{len(missing)} of {len(want)} episodes missing (e.g. {missing[0][0]} repeat {missing[0][1]}; a "
            "sample, a filter, a shard or an unfinished run)"
        )
    if beyond:
        return f"{len(beyond)} rows beyond the protocol (e.g. {beyond[0][0]} repeat {beyond[0][1]})"
    if stopped is not None:
        decision = decide_split(
            [r for r in rows if int(r["repeat"]) < rounds], rounds, Design(**protocol.adaptive)
        )
        if decision.stopped != stopped["stopped"]:
            return f"its rows give {decision.stopped!r} after {rounds} rounds, its record says {stopped['stopped']!r}"
    return ""


def check_own_run(rows: list[dict], bench, run: dict, results: Path) -> Check:
    """A run that claims no protocol: every split it chose whole for its own repeats, value filter and shard, or
    for an adaptive split the rounds its stopping record says, with the decision its rows give; no row beyond."""
    from roboview.eval.running.results import shard_of
    from roboview.eval.statistics.adaptive import Design, decide_split

    values = set(run.get("values") or [])
    shard = run.get("shard")
    n_shards = int(shard.split("/")[1]) if shard else 0
    index = int(shard.split("/")[0]) if shard else 0
    have = {(r["instance_id"], r["repeat"]) for r in rows}
    adaptive = (read_record(results) or {}) if run.get("adaptive") else {}
    repeats_of = run.get("n_repeats", {})
    beyond = [r for r in rows if r["split"] not in repeats_of]
    problems = [f"{len(beyond)} rows of splits the run did not choose"] if beyond else []
    summary = []
    for split, repeats in repeats_of.items():
        items = [i for i in bench.splits.get(split, []) if not values or i.record["value"] in values]
        items = [i for i in items if not n_shards or shard_of(i.record["instance_id"], n_shards) == index]
        if split not in bench.splits:
            problems.append(f"{split}: not in the benchmark")
            continue
        stopped = adaptive.get("splits", {}).get(split)
        if run.get("adaptive") and "|" not in split and stopped is None and items:
            problems.append(
                f"{split}: adaptive run with no stopping record (unfinished: rerun the same command)"
            )
            continue
        rounds = stopped["rounds"] if stopped else repeats
        missing = [
            (i.record["instance_id"], r)
            for i in items
            for r in range(rounds)
            if (i.record["instance_id"], r) not in have
        ]
        over = [r for r in rows if r["split"] == split and int(r["repeat"]) >= rounds]
        if not any((i.record["instance_id"], 0) in have for i in items) and items:
            problems.append(f"{split}: missing (no episode of its {len(items)} instances)")
        elif missing:
            problems.append(
                f"{split}: {len(missing)} of {len(items) * rounds} episodes missing "
                f"(e.g. {missing[0][0]} repeat {missing[0][1]}; a sample or an unfinished run)"
            )
        elif over:
            problems.append(f"{split}: {len(over)} rows beyond its {rounds} repeats")
        elif stopped:
            design = Design(**adaptive["design"])
            split_rows = [r for r in rows if r["split"] == split and r["repeat"] < rounds]
            decision = decide_split(split_rows, rounds, design)
            if decision.stopped != stopped["stopped"]:
                problems.append(
                    f"{split}: its rows give {decision.stopped!r} after {rounds} rounds, its record says "
                    f"{stopped['stopped']!r}"
                )
        summary.append(f"{split} {len(items)}×{rounds}")
    return Check(
        "complete",
        not problems,
        "; ".join(problems) if problems else "every split complete: " + ", ".join(summary),
    )


def verify_results(
    results: str | Path,
    benchmark: str | Path | None = None,
    replay: int = 0,
    detect: float = 0.05,
    loaded=None,
    replayer=None,
) -> Report:
    """A results folder against its benchmark (`benchmark`, else the one its provenance names): the table's schema
    first, then files, identity, the record, instances, seeds, duplicates, isolation, completeness for the protocol
    it claims, infrastructure errors, plausibility, conformance re-derived, and with `replay` > 0 that many episodes
    drawn at random and re-run here (`detect`: the forged share the stated guarantee speaks of). `loaded`: that
    benchmark already loaded and checked (a board verifying many bundles against one); `replayer`: the
    `replay.Replayer` whose workers outlive this call (a board's). ResultsError for a folder that holds no readable
    results; ValueError when no benchmark can be found."""
    from roboview.benchmark.format import BenchmarkError, load_benchmark
    from roboview.eval.verification.replay import check_replay

    start = time.perf_counter()
    results = Path(results)
    table, run = read_table(results)
    schema = check_schema(table)
    if not schema.passed:  # nothing else can be read from rows that are not episode rows
        return Report([schema], time.perf_counter() - start)
    rows = table.to_pylist()
    root = benchmark_path(results, benchmark)
    try:
        same = loaded is not None and Path(loaded.path).resolve() == Path(root).resolve()
        bench = loaded if same else load_benchmark(root)
    except BenchmarkError as exc:
        return Report([schema, Check("benchmark", False, str(exc))], time.perf_counter() - start)
    checks = [schema, Check("benchmark", True, f"{root}: version {bench.version}, every cell as built")]
    checks += _file_checks(results, run, bench)
    checks.append(check_record(rows, run, _table_policy(table), provenance.read(results)))
    checks += check_rows(rows, bench)
    checks.append(check_isolation(rows))
    complete, coverage = check_complete(rows, bench, run, results)
    checks += [complete, check_infrastructure(rows), check_plausible(rows, run.get("max_steps"))]
    checks.append(check_conformance(rows, results, read_manifest(root).get("stack")))
    replayed = None
    if replay > 0:
        check, replayed = check_replay(rows, bench, run, replay, detect, replayer)
        checks.append(check)
    return Report(checks, time.perf_counter() - start, coverage=coverage, replay=replayed)


def _table_policy(table) -> str | None:
    """The policy episodes.parquet's own metadata records (None: it records none)."""
    raw = (table.schema.metadata or {}).get(b"roboview_policy")
    return None if raw is None else raw.decode()


def _file_checks(results: Path, run: dict, bench) -> list[Check]:
    """A published bundle's files against bundle.json; the benchmark version the table, run.json and the
    benchmark agree on."""
    from roboview.eval.running.results import read_version

    checks = []
    problems = manifest_problems(results)
    if problems is not None:  # a published bundle: every file as bundle.json records it
        checks.append(
            Check(
                "files",
                not problems,
                f"every file as {BUNDLE_FILE} records it"
                if not problems
                else f"{len(problems)} file(s) differ from {BUNDLE_FILE}: {listed(problems)}",
            )
        )
    recorded = read_version(results / PARQUET)
    same = recorded == bench.version == run.get("benchmark_version")
    checks.append(
        Check(
            "identity",
            same,
            f"results of benchmark {recorded}"
            + ("" if same else f", not of {bench.version} (another benchmark or version)"),
        )
    )
    return checks


def check_isolation(rows: list[dict]) -> Check:
    """The isolation certificate: in every (context, repeat) block only the factor differs."""
    from roboview.eval.running import isolation

    certificate = isolation.verify(pd.DataFrame(rows)) if rows else {}
    unrecorded = [s for s, r in certificate.items() if not r["recorded"]]
    violations = {s: len(r["violations"]) for s, r in certificate.items() if r["violations"]}
    return Check(
        "isolation",
        not unrecorded and not violations,
        f"{sum(r['blocks'] for r in certificate.values())} blocks, only the factor differs in each"
        if not unrecorded and not violations
        else "; ".join(
            [f"{s}: no certificate recorded" for s in unrecorded]
            + [f"{s}: {n} blocks where more than the factor differs" for s, n in violations.items()]
        ),
    )


def check_infrastructure(rows: list[dict]) -> Check:
    """No episode that infrastructure ended: such rows are no results (a rerun runs them)."""
    infra = Counter(r["split"] for r in rows if r.get(STATUS) == INFRA_ERROR)
    return Check(
        "infrastructure",
        not infra,
        "no episode ended by infrastructure"
        if not infra
        else f"{sum(infra.values())} episodes ended by infrastructure, not results ("
        + ", ".join(f"{s}: {n}" for s, n in infra.items())
        + "); rerun the same command to re-run them",
    )
