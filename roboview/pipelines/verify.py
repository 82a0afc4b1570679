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

Every split must be complete for the benchmark's protocol the results claim (run.json's `protocol`, from
`roboview-evaluate --eval.protocol`): judged against the benchmark's declaration, so a split left out, a value
filtered away or repeats padded all show. Results that cover only some of the protocol's splits are `partial`.

    roboview-verify --results=outputs/eval/vision --replay.detect=0.05 --replay.confidence=0.95

re-runs episodes drawn at random here (nothing in the folder predicts which), as many as the guarantee needs: any
forgery of ≥ 5 % of the rows is caught with probability ≥ 95 % (59 episodes). `--replay=N` (or `--replay.n=N`)
fixes the number instead; the line printed states the guarantee N gives, and that a smaller forgery can pass.
verify.json in the results folder records the checks, the coverage and the replay.

Exit status: 0 when everything checked holds, 1 otherwise (2 for unusable input).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.verification import Report, verify_benchmark, verify_results
from roboview.pipelines._cli import BenchmarkPath, ReplayConfig, cli_main, replay_flag


@dataclass
class VerifyConfig:
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # A results folder (roboview.pipelines.evaluate --output_dir) to verify against its benchmark; empty: verify the
    # benchmark (--benchmark.path) on this machine.
    results: str = ""
    # With --results: re-run episodes drawn at random here with the policy run.json records, and require each to end
    # as recorded (success, steps, failure reason): --replay.detect=F --replay.confidence=C sizes the sample to
    # catch any forgery of ≥ F of the rows with probability ≥ C; --replay=N fixes N. Needs the policy deterministic
    # and reachable (a checkpoint on disk, a scripted agent, a server that answers).
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    # With --benchmark.path alone: re-render and re-simulate only the first N instances of the reference sample
    # (a quick look; the verdict then speaks for those only). 0: all of them.
    sample: int = 0

    def __post_init__(self) -> None:
        if self.sample < 0:
            raise ValueError(f"--sample={self.sample} must be 0 or more")
        self.replay.size()  # a bad detect / confidence fails here
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


def run(cfg: VerifyConfig) -> Report:
    if cfg.results:
        detect = cfg.replay.detect or 0.05
        report = verify_results(cfg.results, cfg.benchmark.path or None, cfg.replay.size(), detect)
        write_verify_json(Path(cfg.results), report)
        return report
    return verify_benchmark(cfg.benchmark.path, cfg.sample)


def write_verify_json(results: Path, report: Report) -> None:
    """verify.json beside the results: every check, the coverage and the replay (a published bundle keeps the
    verify.json its staging wrote; a read-only folder: skipped)."""
    import json

    from roboview.eval.reporting.bundle import BUNDLE_FILE, VERIFY_FILE

    if (results / BUNDLE_FILE).is_file():
        return
    try:
        (results / VERIFY_FILE).write_text(json.dumps(report.record(), indent=2, default=str) + "\n")
    except OSError:
        pass


def _summary(cfg: VerifyConfig, result: Report) -> None:
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


def main(args: list[str] | None = None) -> Report:
    import sys

    from roboview.eval.running.results import ResultsError

    argv = replay_flag(args if args is not None else sys.argv[1:])
    return cli_main(VerifyConfig, run, _summary, (ValueError, ResultsError), argv)


if __name__ == "__main__":
    main()
