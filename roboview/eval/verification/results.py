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

from roboview.core.folders import folder_problem
from roboview.eval.reporting.bundle import BUNDLE_FILE, manifest_problems
from roboview.eval.running.row import INFRA_ERROR, STATUS
from roboview.eval.verification.report import Check, Report, listed


def benchmark_path(results: str | Path, benchmark: str | Path | None = None) -> Path:
    """The benchmark folder `results` are checked against: `benchmark` if given, else the one its provenance
    names."""
    from roboview.eval.running import provenance

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
    from roboview.eval.running.results import PARQUET, RUN_FILE, ResultsError, check_format

    advice = "give the folder roboview-evaluate wrote (--output_dir)"
    problem = folder_problem(results, "results", RUN_FILE, advice) or folder_problem(
        results, "results", PARQUET, advice
    )
    if problem:
        raise ResultsError(problem)
    check_format(results / PARQUET)  # refuses other results formats with its own message
    return pq.read_table(results / PARQUET).to_pylist(), json.loads((results / RUN_FILE).read_text())


def check_rows(rows: list[dict], bench) -> list[Check]:
    """Instances, seeds and duplicates of the rows against the benchmark's records."""
    records = {i.record["instance_id"]: i.record for items in bench.splits.values() for i in items}
    return [check_instances(rows, records), check_seeds(rows, records), check_duplicates(rows)]


def check_instances(rows: list[dict], records: dict[str, dict]) -> Check:
    """Every row an instance of the benchmark, its instance columns as the benchmark records them."""
    unknown = [r["instance_id"] for r in rows if r["instance_id"] not in records]
    edited = []
    for row in rows:
        record = records.get(row["instance_id"])
        cols = [c for c, v in record.items() if row.get(c) != v] if record is not None else []
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


def check_complete(rows: list[dict], bench, run: dict, results: Path) -> Check:
    """Every split the run chose: all its instances (after the run's value filter and shard) × its repeats, or,
    for an adaptive split, the rounds its stopping record says, with the decision its rows give."""
    from roboview.eval.running.results import shard_of
    from roboview.eval.statistics.adaptive import Design, decide_split, read_record

    values = set(run.get("values") or [])
    shard = run.get("shard")
    n_shards = int(shard.split("/")[1]) if shard else 0
    index = int(shard.split("/")[0]) if shard else 0
    have = {(r["instance_id"], r["repeat"]) for r in rows}
    adaptive = (read_record(results) or {}) if run.get("adaptive") else {}
    problems, summary = [], []
    for split, repeats in run.get("n_repeats", {}).items():
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
        if not any((i.record["instance_id"], 0) in have for i in items) and items:
            problems.append(f"{split}: missing (no episode of its {len(items)} instances)")
        elif missing:
            problems.append(
                f"{split}: {len(missing)} of {len(items) * rounds} episodes missing "
                f"(e.g. {missing[0][0]} repeat {missing[0][1]}; a sample or an unfinished run)"
            )
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


def verify_results(results: str | Path, benchmark: str | Path | None = None, replay: int = 0) -> Report:
    """A results folder against its benchmark (`benchmark`, else the one its provenance names): files, identity,
    instances, seeds, duplicates, isolation, completeness, infrastructure errors, conformance, and with `replay`
    > 0 that many episodes re-run here. ResultsError for a folder that holds no results; ValueError when no
    benchmark can be found."""
    from roboview.benchmark.format import BenchmarkError, load_benchmark
    from roboview.eval.running.results import read_version
    from roboview.eval.verification.replay import check_replay

    start = time.perf_counter()
    results = Path(results)
    rows, run = read_rows(results)
    root = benchmark_path(results, benchmark)
    try:
        bench = load_benchmark(root)
    except BenchmarkError as exc:
        return Report([Check("benchmark", False, str(exc))], time.perf_counter() - start)
    checks = [Check("benchmark", True, f"{root}: version {bench.version}, every cell as built")]
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
    recorded = read_version(results / "episodes.parquet")
    same = recorded == bench.version == run.get("benchmark_version")
    checks.append(
        Check(
            "identity",
            same,
            f"results of benchmark {recorded}"
            + ("" if same else f", not of {bench.version} (another benchmark or version)"),
        )
    )
    checks += check_rows(rows, bench)
    checks.append(check_isolation(rows))
    checks.append(check_complete(rows, bench, run, results))
    checks.append(check_infrastructure(rows))
    checks.append(check_conformance(rows, results))
    if replay > 0:
        checks.append(check_replay(rows, bench, run, replay))
    return Report(checks, time.perf_counter() - start)


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


def check_conformance(rows: list[dict], results: Path) -> Check:
    """Every row from a stack whose conformance was identical or equivalent, as provenance.json records it."""
    from roboview.eval.running import provenance

    verdicts = Counter(r.get("conformance") or "not recorded" for r in rows)
    entries = [e for e in provenance.read(results) if e.get("conformance")]
    ok = bool(rows) and set(verdicts) <= {"identical", "equivalent"} and bool(entries)
    stacks = sorted(
        {json.dumps(e["conformance"].get("stack", {}).get("renderer", {}), sort_keys=True) for e in entries}
    )
    return Check(
        "conformance",
        ok,
        ", ".join(f"{n} rows {v}" for v, n in sorted(verdicts.items()))
        + f"; {len(entries)} run(s) recorded their stack ({len(stacks)} renderer(s))"
        + (
            ""
            if ok
            else " — every row must come from a stack whose conformance is identical or "
            "equivalent, recorded in provenance.json"
        ),
    )
