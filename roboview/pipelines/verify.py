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

from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.verification import Report, verify_benchmark, verify_results
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


def run(cfg: VerifyConfig) -> Report:
    if cfg.results:
        return verify_results(cfg.results, cfg.benchmark.path or None, cfg.replay)
    return verify_benchmark(cfg.benchmark.path, cfg.sample)


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
    from roboview.eval.running.results import ResultsError

    return cli_main(VerifyConfig, run, _summary, (ValueError, ResultsError), args)


if __name__ == "__main__":
    main()
