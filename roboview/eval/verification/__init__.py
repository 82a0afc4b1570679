"""Verification as a library: a benchmark on this machine (`verify_benchmark`) and a result bundle against its
benchmark (`verify_results`), each returning a `Report` of named checks. `roboview-verify` prints one;
`roboview-publish` and `roboview-leaderboard` call the same functions, so no verb imports another.

    from roboview.eval.verification import verify_results
    report = verify_results("outputs/eval/vision", benchmark="outputs/benchmark", replay=20)
    report.passed, [(c.name, c.passed, c.detail) for c in report.checks]
"""

from roboview.eval.verification.benchmark import verify_benchmark
from roboview.eval.verification.report import Check, Report
from roboview.eval.verification.results import benchmark_path, verify_results

__all__ = ["Check", "Report", "benchmark_path", "verify_benchmark", "verify_results"]
