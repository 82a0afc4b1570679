"""What trusting a number costs: the start-of-run conformance check and `roboview.pipelines.verify --results` on a large
result bundle.

    python -m benchmarks.verify_rate --benchmark.path=outputs/demo/benchmark [--rows=10000] \
        [--output=outputs/bench/verify.json]

1. The conformance check as `roboview.pipelines.evaluate` runs it before its first episode: measured (empty cache), then
   read from the cache (the stack described, the verdict reused), and `roboview.pipelines.verify --benchmark.path`'s check.
2. A results folder of `--rows` episodes: the expert runs every instance of the benchmark once, then the rows are
   repeated over repeats 1, 2, … with each repeat's common-random-number seed (what a long run of a deterministic
   policy writes) until `--rows`; `roboview.pipelines.verify --results` is timed on it (it must pass).

Prints one line per figure and writes them as JSON (docs/performance.md).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.parquet as pq

from roboview.eval.running.results import PARQUET
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class VerifyBenchConfig:
    benchmark: BenchmarkPath = field(default_factory=lambda: BenchmarkPath("outputs/demo/benchmark"))
    # Episode rows of the synthetic result bundle verified.
    rows: int = 10_000
    # Where the figures go (JSON).
    output: str = "outputs/bench/verify.json"

    def __post_init__(self) -> None:
        if self.rows <= 0:
            raise ValueError(f"--rows={self.rows} must be a positive count")
        if not (Path(self.benchmark.path) / "benchmark.json").is_file():
            raise ValueError(
                f"--benchmark.path={self.benchmark.path} holds no benchmark; build one with "
                "`roboview-build-benchmark --preset=tiny --output_dir=outputs/demo/benchmark`"
            )


def _timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def run(cfg: VerifyBenchConfig) -> dict:
    from roboview.benchmark import conformance
    from roboview.benchmark.format import read_manifest
    from roboview.eval.running.results import EpisodeStore
    from roboview.pipelines.verify import VerifyConfig
    from roboview.pipelines.verify import run as verify
    from roboview.variation.instances import episode_seed

    root = Path(cfg.benchmark.path)
    version = read_manifest(root)["benchmark_version"]
    out: dict = {"benchmark": version, "rows": cfg.rows}
    with tempfile.TemporaryDirectory(prefix="roboview-verify-") as scratch:
        scratch = Path(scratch)
        report, out["at_start_measured_s"] = _timed(
            lambda: conformance.at_start(root, version, scratch / "cache")
        )
        _, out["at_start_cached_s"] = _timed(lambda: conformance.at_start(root, version, scratch / "cache"))
        out["check_s"] = round(report.seconds, 2)
        out["verdict"] = report.verdict
        print(
            f"[verify_rate] start-of-run check: {out['at_start_measured_s']:.1f} s measured "
            f"({report.seconds:.1f} s re-rendering and re-simulating {len(report.checks)} checks), "
            f"{out['at_start_cached_s']:.1f} s from the cache; verdict {report.verdict}",
            flush=True,
        )

        base = scratch / "base"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "roboview.pipelines.evaluate",
                f"--benchmark.path={root}",
                "--policy.type=expert",
                "--eval.n_repeats=1",
                f"--output_dir={base}",
            ],
            check=True,
            capture_output=True,
        )
        run_info = json.loads((base / "run.json").read_text())
        rows = pq.read_table(base / PARQUET).to_pylist()
        repeats = -(-cfg.rows // len(rows))
        run_info["n_repeats"] = {split: repeats for split in run_info["n_repeats"]}
        run_info.pop("results_format", None)
        big = scratch / "big"
        store = EpisodeStore(big, run_info)
        store.add_many(
            [
                {**row, "repeat": r, "episode_seed": episode_seed(row["context_id"], r)}
                for r in range(repeats)
                for row in rows
            ]
        )
        store.close()
        (big / "provenance.json").write_text((base / "provenance.json").read_text())
        result, out["verify_results_s"] = _timed(
            lambda: verify(VerifyConfig(BenchmarkPath(str(root)), str(big)))
        )
        out["verify_rows"] = len(store.rows)
        out["verify_passed"] = result.passed
        print(
            f"[verify_rate] verify --results on {len(store.rows):,} rows: {out['verify_results_s']:.1f} s "
            f"({'passed' if result.passed else 'FAILED'})",
            flush=True,
        )
    out = {k: round(v, 2) if isinstance(v, float) else v for k, v in out.items()}
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(VerifyBenchConfig, run, None, (ValueError,), args)


if __name__ == "__main__":
    main()
