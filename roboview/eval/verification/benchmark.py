"""A benchmark on this machine: identity (every cell as built) and conformance (the reference sample
re-rendered and re-simulated; verdict identical, equivalent or different)."""

from __future__ import annotations

import time
from pathlib import Path

from roboview.eval.verification.report import Check, Report


def verify_benchmark(root: str | Path, sample: int = 0) -> Report:
    """Every table's cells against the build's checksums, then the conformance check: the reference sample
    re-rendered and re-simulated on this machine (`sample` > 0: its first `sample` instances only)."""
    from roboview.benchmark import conformance
    from roboview.benchmark.format import BenchmarkError, read_manifest, verify_table
    from roboview.sim import stack

    root = Path(root)
    start = time.perf_counter()
    checks = []
    try:
        manifest = read_manifest(root)
    except BenchmarkError as exc:
        return Report([Check("identity", False, str(exc))], time.perf_counter() - start)
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
    return Report(checks, time.perf_counter() - start, report.verdict)
