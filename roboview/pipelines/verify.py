"""Verify a benchmark on this machine, or a result bundle against its benchmark.

    roboview-verify --benchmark.path=outputs/benchmark
    roboview-verify --results=outputs/eval/vision [--benchmark.path=outputs/benchmark]

With `--benchmark.path` alone: every table's cells against the build's checksums, then the conformance check
(the reference sample re-rendered and re-simulated on this machine: per image the share of differing pixels,
the largest level difference, PSNR and the pixels of differing regions; per rollout the joint and object
error), one line per check, and the verdict: identical, equivalent or different.

With `--results`: a results folder (roboview.pipelines.evaluate's --output_dir, or a merge of shards) against its
benchmark (default: the one its provenance names). Every row's instance must exist with identical content;
its episode seed must be the common-random-number seed of its (context, repeat); no (instance, repeat) may
appear twice; the isolation certificate must hold; each split must be complete for its protocol (an adaptive
split: its stopping record must follow from its rows); no episode may be an uncounted infrastructure error;
every row must record its conformance verdict, none `different`. Prints a pass/fail table with reasons.

Exit status: 0 when everything checked holds, 1 otherwise (2 for unusable input).
"""

from __future__ import annotations

import json
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.parquet as pq

from roboview.core.folders import folder_problem
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class VerifyConfig:
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # A results folder (roboview.pipelines.evaluate --output_dir) to verify against its benchmark; empty: verify the
    # benchmark (--benchmark.path) on this machine.
    results: str = ""
    # With --results: re-run this many of its episodes (a fixed sample; all when larger) with the policy run.json
    # records, here, and require each to end as recorded (success, steps, failure reason). Catches an edited row;
    # needs the policy to be deterministic and reachable (a checkpoint on disk, a server that answers).
    replay: int = 0
    # With --benchmark.path alone: re-render and re-simulate only the first N instances of the reference sample
    # (a quick look; the verdict then speaks for those only). 0: all of them.
    sample: int = 0

    def __post_init__(self) -> None:
        for flag in ("replay", "sample"):
            if getattr(self, flag) < 0:
                raise ValueError(f"--{flag}={getattr(self, flag)} must be 0 or more")
        if not self.results and not self.benchmark.path:
            raise ValueError(
                "give --benchmark.path=DIR (verify a benchmark on this machine) or --results=DIR "
                "(verify a results folder against its benchmark)"
            )
        from roboview.eval.running.inputs import benchmark_folder_problem, results_folder_problem

        problem = self.results and results_folder_problem(
            Path(self.results), f" (verify a benchmark with --benchmark.path={self.results})"
        )
        if problem:
            raise ValueError(f"--results: {problem}")
        problem = self.benchmark.path and benchmark_folder_problem(Path(self.benchmark.path))
        if problem:
            raise ValueError(f"--benchmark.path: {problem}")


@dataclass
class Check:
    name: str
    passed: bool
    detail: str


@dataclass
class VerifyResult:
    checks: list[Check]
    seconds: float
    verdict: str | None = None  # the conformance verdict (benchmark mode)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


# --- a benchmark on this machine -----------------------------------------------------------------------


def verify_benchmark(root: Path, sample: int = 0) -> VerifyResult:
    from roboview.benchmark import conformance
    from roboview.benchmark.format import BenchmarkError, read_manifest, verify_table
    from roboview.sim import stack

    start = time.perf_counter()
    checks = []
    try:
        manifest = read_manifest(root)
    except BenchmarkError as exc:
        return VerifyResult([Check("identity", False, str(exc))], time.perf_counter() - start)
    tables = sorted([*root.glob("data/*.parquet"), *root.glob("rejected/*.parquet")])
    for path in tables:
        try:
            rows = verify_table(root, path, manifest)
            checks.append(
                Check(
                    f"content {path.relative_to(root).with_suffix('')}",
                    True,
                    f"{len(rows)} rows, every cell as built",
                )
            )
        except BenchmarkError as exc:
            checks.append(Check(f"content {path.relative_to(root).with_suffix('')}", False, str(exc)))
    report = conformance.check(root, limit=sample or None)
    for line in report.lines():
        print(line)
    differences = stack.differences(manifest.get("stack"), report.stack)
    checks.append(
        Check("stack", True, "the same as the build's" if not differences else "; ".join(differences))
    )
    d = report.drift
    checks.append(
        Check(
            "conformance",
            report.verdict != "different",
            f"{report.verdict}: {d['images_identical']}/{d['images']} images and {d['physics_identical']}/"
            f"{d['physics']} rollouts bit-identical; ≤ {d['pixel_fraction_max']:.3%} pixels differ (max Δ "
            f"{d['max_level_diff']}, region px {d['region_pixels_max']}); joints ≤ {d['joint_max']:.1e} rad, "
            f"object ≤ {d['object_error_m_max']:.1e} m",
        )
    )
    return VerifyResult(checks, time.perf_counter() - start, report.verdict)


# --- a results folder against its benchmark --------------------------------------------------------------


def benchmark_path(cfg: VerifyConfig, results: Path) -> Path:
    """The benchmark folder `results` are checked against: --benchmark.path, else the one its provenance names."""
    from roboview.eval.running import provenance

    if cfg.benchmark.path:
        return Path(cfg.benchmark.path)
    recorded = [e.get("benchmark_path") for e in provenance.read(results) if e.get("benchmark_path")]
    if recorded and Path(recorded[-1]).is_dir():
        return Path(recorded[-1])
    raise ValueError(
        f"{results} does not name a benchmark folder that exists here "
        f"({recorded[-1] if recorded else 'none recorded'}); pass --benchmark.path=DIR"
    )


def _rows(results: Path) -> tuple[list[dict], dict]:
    """The results' rows (as stored) and run.json; ResultsError for a folder that holds none."""
    from roboview.eval.running.results import PARQUET, RUN_FILE, ResultsError, check_format

    advice = "give the folder roboview.pipelines.evaluate wrote (--output_dir)"
    problem = folder_problem(results, "results", RUN_FILE, advice) or folder_problem(
        results, "results", PARQUET, advice
    )
    if problem:
        raise ResultsError(problem)
    check_format(results / PARQUET)  # refuses other results formats with its own message
    return pq.read_table(results / PARQUET).to_pylist(), json.loads((results / RUN_FILE).read_text())


def _listed(items: list, limit: int = 3) -> str:
    return ", ".join(map(str, items[:limit])) + (f" … ({len(items)} in all)" if len(items) > limit else "")


def check_rows(rows: list[dict], bench) -> list[Check]:
    """Instances, seeds and duplicates of the rows against the benchmark's records."""
    from roboview.variation.instances import episode_seed

    records = {i.record["instance_id"]: i.record for items in bench.splits.values() for i in items}
    unknown = [r["instance_id"] for r in rows if r["instance_id"] not in records]
    edited = []
    for row in rows:
        record = records.get(row["instance_id"])
        if record is not None:
            cols = [c for c, v in record.items() if row.get(c) != v]
            if cols:
                edited.append(f"{row['instance_id']} repeat {row['repeat']} ({', '.join(cols)})")
    checks = [
        Check(
            "instances",
            not unknown and not edited,
            f"{len(rows)} rows, each an instance of the benchmark with identical content"
            if not unknown and not edited
            else "; ".join(
                filter(
                    None,
                    [
                        f"{len(unknown)} rows name instances the benchmark does not hold: {_listed(sorted(set(unknown)))}"
                        if unknown
                        else "",
                        f"{len(edited)} rows differ from their instance's record: {_listed(edited)}"
                        if edited
                        else "",
                    ],
                )
            ),
        )
    ]
    bad_seeds = [
        f"{r['instance_id']} repeat {r['repeat']} (seed {r.get('episode_seed')}, expected "
        f"{episode_seed(records[r['instance_id']]['context_id'], r['repeat'])})"
        for r in rows
        if r["instance_id"] in records
        and r.get("episode_seed") != episode_seed(records[r["instance_id"]]["context_id"], r["repeat"])
    ]
    checks.append(
        Check(
            "seeds",
            not bad_seeds,
            "every episode seed is its (context, repeat)'s common-random-number seed"
            if not bad_seeds
            else f"{len(bad_seeds)} rows with another seed: {_listed(bad_seeds)}",
        )
    )
    counts = Counter((r["instance_id"], r["repeat"]) for r in rows)
    twice = [f"{i} repeat {r} ×{n}" for (i, r), n in counts.items() if n > 1]
    checks.append(
        Check(
            "duplicates",
            not twice,
            "no (instance, repeat) twice"
            if not twice
            else f"{len(twice)} (instance, repeat) pairs appear more than once: {_listed(twice)}",
        )
    )
    return checks


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


def verify_results(cfg: VerifyConfig) -> VerifyResult:
    from roboview.benchmark.format import BenchmarkError, load_benchmark
    from roboview.eval.running import isolation, provenance
    from roboview.eval.running.results import read_version

    start = time.perf_counter()
    results = Path(cfg.results)
    rows, run = _rows(results)
    root = benchmark_path(cfg, results)
    try:
        bench = load_benchmark(root)
    except BenchmarkError as exc:
        return VerifyResult([Check("benchmark", False, str(exc))], time.perf_counter() - start)
    checks = [Check("benchmark", True, f"{root}: version {bench.version}, every cell as built")]
    from roboview.eval.reporting.bundle import BUNDLE_FILE, manifest_problems

    problems = manifest_problems(results)
    if problems is not None:  # a published bundle: every file as bundle.json records it
        checks.append(
            Check(
                "files",
                not problems,
                f"every file as {BUNDLE_FILE} records it"
                if not problems
                else f"{len(problems)} file(s) differ from {BUNDLE_FILE}: {_listed(problems)}",
            )
        )
    recorded = read_version(results / "episodes.parquet")
    checks.append(
        Check(
            "identity",
            recorded == bench.version == run.get("benchmark_version"),
            f"results of benchmark {recorded}"
            + (
                ""
                if recorded == bench.version == run.get("benchmark_version")
                else f", not of {bench.version} (another benchmark or version)"
            ),
        )
    )
    checks += check_rows(rows, bench)
    import pandas as pd

    frame = pd.DataFrame(rows)
    certificate = isolation.verify(frame) if rows else {}
    unrecorded = [s for s, r in certificate.items() if not r["recorded"]]
    violations = {s: len(r["violations"]) for s, r in certificate.items() if r["violations"]}
    checks.append(
        Check(
            "isolation",
            not unrecorded and not violations,
            f"{sum(r['blocks'] for r in certificate.values())} blocks, only the factor differs in each"
            if not unrecorded and not violations
            else "; ".join(
                [f"{s}: no certificate recorded" for s in unrecorded]
                + [f"{s}: {n} blocks where more than the factor differs" for s, n in violations.items()]
            ),
        )
    )
    checks.append(check_complete(rows, bench, run, results))
    infra = Counter(r["split"] for r in rows if r.get("status") == "infra_error")
    checks.append(
        Check(
            "infrastructure",
            not infra,
            "no episode ended by infrastructure"
            if not infra
            else f"{sum(infra.values())} episodes ended by infrastructure, not results ("
            + ", ".join(f"{s}: {n}" for s, n in infra.items())
            + "); rerun the same command to re-run them",
        )
    )
    verdicts = Counter(r.get("conformance") or "not recorded" for r in rows)
    entries = [e for e in provenance.read(results) if e.get("conformance")]
    ok = bool(rows) and set(verdicts) <= {"identical", "equivalent"} and bool(entries)
    stacks = sorted(
        {json.dumps(e["conformance"].get("stack", {}).get("renderer", {}), sort_keys=True) for e in entries}
    )
    checks.append(
        Check(
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
    )
    if cfg.replay > 0:
        checks.append(check_replay(rows, bench, run, cfg.replay))
    return VerifyResult(checks, time.perf_counter() - start)


REPLAYED = ("success", "steps", "failure_reason")  # what a replayed episode must reproduce


def replay_sample(rows: list[dict], n: int) -> list[dict]:
    """`n` rows in a fixed order (by a hash of instance and repeat): the same sample on every machine."""
    import hashlib

    def key(row: dict) -> str:
        return hashlib.sha256(f"{row['instance_id']}:{row['repeat']}".encode()).hexdigest()

    return sorted((r for r in rows if r.get("status") != "infra_error"), key=key)[:n]


def check_replay(rows: list[dict], bench, run: dict, n: int) -> Check:
    """Re-run a sample of the episodes with the recorded policy; every one must end as its row says."""
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.policies.types import policy_config

    sample = replay_sample(rows, n)
    try:
        settings = dict(run.get("policy_options") or {})
        if run.get("policy_path"):
            settings["path"] = run["policy_path"]
        if run.get("policy_name"):
            settings["name"] = run["policy_name"]
        policy = policy_config(run["policy"], **settings)
    except Exception as exc:  # any failure to rebuild the policy is the check's answer
        return Check("replay", False, f"cannot rebuild policy {run.get('policy')!r} from run.json: {exc}")
    items = {i.record["instance_id"]: i for items in bench.splits.values() for i in items}
    workers: dict[str, EvalWorker] = {}
    differ = []
    try:
        for row in sample:
            item = items[row["instance_id"]]
            task = item.instance.task
            if task not in workers:
                workers[task] = EvalWorker(
                    WorkerSpec(policy, run.get("image_size", 224), run.get("max_steps", 120), task=task)
                )
            again = workers[task].run(WorkItem(item, int(row["repeat"]))).row
            changed = [
                f"{k} {row.get(k)!r} → {again.get(k)!r}"
                for k in REPLAYED
                if (row.get(k) or None) != (again.get(k) or None)
            ]
            if changed:
                differ.append(f"{row['instance_id']} repeat {row['repeat']}: {', '.join(changed)}")
    finally:
        for worker in workers.values():
            worker.close()
    return Check(
        "replay",
        not differ,
        f"{len(sample)} episodes re-run with {run['policy']}, each ended as recorded"
        if not differ
        else f"{len(differ)} of {len(sample)} re-run episodes end differently from their rows: {_listed(differ)}",
    )


def run(cfg: VerifyConfig) -> VerifyResult:
    if cfg.results:
        return verify_results(cfg)
    return verify_benchmark(Path(cfg.benchmark.path), cfg.sample)


def _summary(cfg: VerifyConfig, result: VerifyResult) -> None:
    width = max(len(c.name) for c in result.checks)
    for c in result.checks:
        print(f"{'PASS' if c.passed else 'FAIL'}  {c.name:<{width}}  {c.detail}")
    failed = sum(not c.passed for c in result.checks)
    what = cfg.results or cfg.benchmark.path
    print(
        f"[verify] {what}: {'passed' if result.passed else f'FAILED ({failed} of {len(result.checks)} checks)'} "
        f"in {result.seconds:.1f} s"
    )
    if not result.passed:
        raise SystemExit(1)


def main(args: list[str] | None = None) -> VerifyResult:
    from roboview.eval.running.results import ResultsError

    return cli_main(VerifyConfig, run, _summary, (ValueError, ResultsError), args)


if __name__ == "__main__":
    main()
