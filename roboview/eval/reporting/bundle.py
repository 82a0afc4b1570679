"""A result bundle: what `roboview.pipelines.publish --results` uploads as a Hub dataset, and the Hub's eval-results file.

The bundle folder holds the results as evaluated (episodes.parquet, run.json, provenance.json and any adaptive
record), the report computed from them (report/metrics.json, report.md, report.html), `verify.json` (every check
`roboview.pipelines.verify --results` made, with the conformance verdicts and simulation stacks the episodes ran on), a
dataset card (README.md: policy, benchmark id, version and content hash, Table 1) and `bundle.json`, the SHA-256
of every other file. `roboview.pipelines.verify` checks a bundle's files against bundle.json, so a file edited after
publication is refused.

The model repo's `.eval_results/<benchmark>.yaml` that a bundle is the source of is written by
roboview.eval.reporting.eval_results.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from roboview.eval.running.results import PARQUET

BUNDLE_FILE = "bundle.json"
VERIFY_FILE = "verify.json"
REPORT_DIR = "report"
CARD_FILE = "README.md"
BUNDLE_FORMAT = 1
# What a results folder holds that a bundle leaves out: the evaluation's journal (episodes.parquet holds every row
# it does), Rerun recordings and a previous bundle manifest.
SKIPPED = ("episodes.jsonl", "*.rrd", BUNDLE_FILE, VERIFY_FILE, CARD_FILE, f"{REPORT_DIR}/*")
HUB = "https://huggingface.co"


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def content_hash(benchmark_manifest: dict[str, Any]) -> str:
    """One SHA-256 over the benchmark's per-table content hashes (every cell of every table)."""
    return hashlib.sha256(json.dumps(benchmark_manifest["content"], sort_keys=True).encode()).hexdigest()


def bundle_files(root: Path) -> list[Path]:
    """Every file of a bundle but bundle.json, relative to its root, sorted."""
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file() and p.name != BUNDLE_FILE)


def write_manifest(root: Path, identity: dict[str, Any]) -> dict[str, Any]:
    manifest = {
        "format": BUNDLE_FORMAT,
        **identity,
        "files": {str(rel): sha256_file(root / rel) for rel in bundle_files(root)},
    }
    (root / BUNDLE_FILE).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return manifest


def manifest_problems(root: Path) -> list[str] | None:
    """None for a folder without bundle.json (a results folder); else the files that differ from it (empty: none)."""
    path = root / BUNDLE_FILE
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
    except ValueError as exc:
        return [f"{BUNDLE_FILE}: not readable JSON ({exc})"]
    recorded = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(recorded, dict):
        return [f"{BUNDLE_FILE}: holds no `files` object (it is a JSON {type(manifest).__name__})"]
    present = {str(p) for p in bundle_files(root)}
    problems = [f"{rel}: missing" for rel in sorted(set(recorded) - present)]
    problems += [f"{rel}: not in {BUNDLE_FILE}" for rel in sorted(present - set(recorded))]
    problems += [
        f"{rel}: edited (SHA-256 differs from {BUNDLE_FILE})"
        for rel in sorted(set(recorded) & present)
        if sha256_file(root / rel) != recorded[rel]
    ]
    return problems


def _skipped(rel: Path) -> bool:
    return any(rel.match(pattern) or str(rel).startswith(pattern.rstrip("*")) for pattern in SKIPPED)


def copy_results(results: Path, staging: Path) -> None:
    for path in sorted(results.rglob("*")):
        rel = path.relative_to(results)
        if path.is_file() and not _skipped(rel):
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, staging / rel)


def table1(report_md: str) -> str:
    """Table 1 of report.md (its heading, table and legend), for the card."""
    match = re.search(r"^## Table 1.*?(?=^## )", report_md, flags=re.S | re.M)
    return match.group(0).strip() if match else ""


def card(
    *,
    policy: str,
    repo_id: str,
    identity: dict[str, Any],
    checks: Sequence[dict[str, Any]],
    report_md: str,
    privileged: bool,
) -> str:
    """The bundle's dataset card (README.md): Hub metadata, then what was evaluated, on what, and Table 1."""
    front = {
        "license": "apache-2.0",
        "pretty_name": f"RoboView-Bias results: {policy}",
        "tags": ["roboview", "robotics", "evaluation", "visual-bias", "leaderboard"],
        "configs": [{"config_name": "episodes", "data_files": PARQUET}],
    }
    bench = identity["benchmark_repo_id"]
    bench_line = (
        f"[`{bench}`]({HUB}/datasets/{bench})" if bench else "a local benchmark folder (not published)"
    )
    lines = [
        "---",
        yaml.safe_dump(front, sort_keys=False).strip(),
        "---",
        "",
        f"# RoboView-Bias results: `{policy}`" + (" (privileged)" if privileged else ""),
        "",
        "Per-episode results of one policy on the RoboView-Bias benchmark, verified by `roboview.pipelines.verify` before "
        "they were published. Rank several bundles with `roboview-leaderboard "
        f"--results={repo_id},...`.",
        "",
        "| | |",
        "|---|---|",
        f"| Policy | `{policy}`"
        + (" — the privileged scripted expert (reads the simulator state)" if privileged else "")
        + " |",
        f"| Benchmark | {bench_line} |",
        f"| Benchmark version | `{identity['benchmark_version']}` |",
        f"| Benchmark content hash | `{identity['benchmark_content_hash']}` |",
        f"| Episodes | {identity['episodes']} |",
        f"| Conformance | {', '.join(identity['conformance'])} |",
        "",
        "## Verification",
        "",
        *_checks_table(checks),
        "",
        table1(report_md),
        "",
        "## Files",
        "",
        "`episodes.parquet` (one row per episode), `run.json`, `provenance.json` (commands, packages, machine, the "
        "simulation stack and its conformance verdict), `report/` (metrics.json, report.md, report.html), "
        f"`{VERIFY_FILE}` (the checks above), `{BUNDLE_FILE}` (the SHA-256 of every file).",
        "",
    ]
    return "\n".join(lines)


def _checks_table(checks: Sequence[dict[str, Any]]) -> list[str]:
    """The verification table: each check passed, failed or not run (`passed` None: the replay staging skips)."""
    result = {None: "not run", True: "pass", False: "FAIL"}
    return [
        "| Check | Result | Detail |",
        "|---|---|---|",
        *(f"| {c['name']} | {result[c['passed']]} | {c['detail']} |" for c in checks),
    ]
