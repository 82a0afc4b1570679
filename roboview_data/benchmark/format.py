"""The frozen benchmark as a Hugging Face dataset folder: parquet splits, rejected table, card.

Everything written is a pure function of the instance records: no timestamps, no machine paths,
so building twice gives the same bytes.
"""

from __future__ import annotations

import csv
import hashlib
import json
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

import datasets
import numpy as np

from roboview_data.variation.instances import canonical_json

MANIFEST = "benchmark.json"
# 2: the `seed` column is the common-random-numbers seed of (context_id, repeat 0); 1 hashed the id.
FORMAT_VERSION = 2
VERDICTS = ("accept", "reject")

_CAMERA = {"name": datasets.Value("string"), "pos": datasets.List(datasets.Value("float64")),
           "quat": datasets.List(datasets.Value("float64")), "fovy": datasets.Value("float64")}
_FAIR_CAMERA = {"camera": datasets.Value("string"), "object_visible": datasets.Value("float64"),
                "object_pixels": datasets.Value("int64"), "object_in_frame": datasets.Value("bool"),
                "box_visible": datasets.Value("float64"), "box_pixels": datasets.Value("int64"),
                "box_in_frame": datasets.Value("bool"), "delta_e_nominal": datasets.Value("float64"),
                "delta_e_table": datasets.Value("float64")}
_STR_COLUMNS = ("instance_id", "split", "factor", "value", "context_id", "color", "camera_pose",
                "camera_euler", "dist_scale", "initial_position", "shape", "instruction", "color_hex")


def instance_features(rejected: bool = False) -> datasets.Features:
    """DESIGN.md's instance record; the rejected table adds who rejected it."""
    cols = {name: datasets.Value("string") for name in _STR_COLUMNS}
    cols |= {"color_rgb": datasets.List(datasets.Value("float64")),
             "color_lab": datasets.List(datasets.Value("float64")),
             "cameras": datasets.List(_CAMERA), "seed": datasets.Value("int64"),
             "fairness": {"cameras": datasets.List(_FAIR_CAMERA), "passed": datasets.Value("bool"),
                          "reject_reason": datasets.Value("string")},
             "preview": datasets.Image()}
    if rejected:
        cols["rejected_by"] = datasets.Value("string")
    return datasets.Features(cols)


@dataclass(frozen=True)
class Decision:
    instance_id: str
    verdict: str
    reviewer: str
    note: str


def read_decisions(path: Path, known_ids: set[str]) -> dict[str, Decision]:
    """Stage-2 adjudication CSV (instance_id, verdict, reviewer, note). A VLM screen writes the same
    file with reviewer "vlm:<model>"; every id must belong to the suite being built."""
    if not path.is_file():
        raise ValueError(f"--decisions={path} does not exist")
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        missing = {"instance_id", "verdict"} - set(reader.fieldnames or [])
        if missing:
            raise ValueError(f"--decisions={path} lacks column(s) {sorted(missing)}; "
                             "expected: instance_id, verdict, reviewer, note")
        rows = list(reader)
    unknown = sorted({r["instance_id"] for r in rows} - known_ids)
    if unknown:
        raise ValueError(f"--decisions={path} names {len(unknown)} instance id(s) not in this suite: "
                         f"{', '.join(unknown[:5])}{' …' if len(unknown) > 5 else ''}")
    bad = sorted({r["verdict"] for r in rows} - set(VERDICTS))
    if bad:
        raise ValueError(f"--decisions={path}: unknown verdict(s) {bad}; allowed: {', '.join(VERDICTS)}")
    return {r["instance_id"]: Decision(r["instance_id"], r["verdict"], r.get("reviewer") or "human",
                                       r.get("note") or "") for r in rows}


def adjudicate(record: dict, decision: Decision | None) -> tuple[bool, str]:
    """(accepted, rejected_by) after stage 1 (the gate) and stage 2 (a decision, if any)."""
    gate_passed = record["fairness"]["passed"]
    if decision is None:
        return gate_passed, "" if gate_passed else "gate"
    if decision.verdict == "reject":
        return False, f"{decision.reviewer}: {decision.note}".rstrip(": ")
    return True, ""  # a reviewer may accept what the gate flagged; the card counts these


def suite_hash(accepted: dict[str, list[dict]]) -> str:
    """SHA-256 over the accepted instance ids per split: ids hash every parameter of an instance."""
    payload = {split: sorted(r["instance_id"] for r in rows) for split, rows in accepted.items()}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


def write_split(rows: list[dict], path: Path, rejected: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    ds = datasets.Dataset.from_list(rows, features=instance_features(rejected))
    ds.to_parquet(str(path))


def _size_category(n: int) -> str:
    for bound, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K")):
        if n < bound:
            return name
    return "100K<n<1M"


def fairness_stats(records: list[dict]) -> dict[str, dict[str, float]]:
    """Per observed camera: quantiles of the measured fairness numbers over all candidates."""
    out: dict[str, dict[str, float]] = {}
    for cam in sorted({c["camera"] for r in records for c in r["fairness"]["cameras"]}):
        rows = [c for r in records for c in r["fairness"]["cameras"] if c["camera"] == cam]
        for key in ("object_visible", "box_visible", "object_pixels", "delta_e_table", "delta_e_nominal"):
            vals = np.array([c[key] for c in rows], dtype=float)
            vals = vals[~np.isnan(vals)]
            if vals.size:
                out.setdefault(cam, {})[key] = [round(float(q), 3) for q in np.percentile(vals, [5, 50, 95])]
    return out


def write_card(out: Path, manifest: dict) -> None:
    splits = manifest["splits"]
    total = sum(s["accepted"] for s in splits.values())
    configs = ["- config_name: default", "  data_files:"]
    for split in splits:
        configs += [f"  - split: {split}", f"    path: data/{split}.parquet"]
    if manifest["rejected"]:
        configs += ["- config_name: rejected", "  data_files:", "  - split: rejected",
                    "    path: rejected/rejected.parquet"]
    table = ["| split | candidates | accepted | rejected (gate) | rejected (review) | accepted over gate |",
             "|---|---|---|---|---|---|"]
    for name, s in splits.items():
        table.append(f"| {name} | {s['candidates']} | {s['accepted']} | {s['rejected_gate']} | "
                     f"{s['rejected_review']} | {s['accepted_over_gate']} |")
    stats = ["| camera | measure | p5 | median | p95 |", "|---|---|---|---|---|"]
    for cam, measures in manifest["fairness_stats"].items():
        for key, (p5, p50, p95) in measures.items():
            stats.append(f"| {cam} | {key} | {p5} | {p50} | {p95} |")
    suite = manifest["suite"]
    text = f"""---
license: apache-2.0
task_categories:
- robotics
tags:
- roboview
- visual-bias
- benchmark
- mujoco
- lerobot
size_categories:
- {_size_category(total)}
pretty_name: RoboView-Bias benchmark instances ({suite['preset']})
configs:
{chr(10).join(configs)}
---

# RoboView-Bias benchmark instances — preset `{suite['preset']}`

Frozen task instances of the RoboView-Bias benchmark: a simulated Franka Panda (MuJoCo) puts one
small object into a yellow box while exactly one visual factor varies per split. Every row is one
instance (DESIGN.md instance record); `preview` shows the observed cameras (front, left_top, wrist)
at t = 0. Load a split with `datasets.load_dataset(PATH, split="color")`.

**Suite hash** (SHA-256 over the accepted instance ids per split): `{manifest['suite_hash']}`
**Benchmark version**: `{manifest['benchmark_version']}`

## Counts

{chr(10).join(table)}

Total accepted: {total}.

## How the instances were built

Structured Variant-Generation Framework with the `{suite['preset']}` preset: union mode
`{suite['union_mode']}` for the generalization context space C_Gen (Structured Union over initial
position × shape × instruction), each visual split V_i × C_Gen(V_i) with every other visual factor
at its baseline (color red, camera pose original, Euler 0,0, distance 0); factorial split
color × camera_pose over colors {', '.join(suite['factorial_colors'])} in the baseline context c*.
Extra Cartesian splits: {suite['cartesian'] or 'none'}. Value subsets: {suite['value_subsets'] or 'none (full factor sets)'}.
`instance_id` is the first 16 hex digits of SHA-256 over the canonical JSON of the instance's
parameters; `seed` (used by env reset) derives from the id alone.

## Perceptual fairness

Stage 1 (programmatic, at t = 0, from every observed camera): segmentation renders give the
object's and box's visible fraction (visible pixels / pixels covered when rendered unoccluded),
pixel area and whether they lie wholly in frame; CIEDE2000 compares the object's rendered color
with its nominal color and with the table. Thresholds: `{json.dumps(manifest['thresholds'])}`.
Stage-1 pass rate: {manifest['gate_pass_rate']:.2%} of {manifest['candidates']} candidates (the build
requires ≥ {manifest['min_pass_rate']:.0%}). Stage 2 (review): {manifest['decisions']} decision(s)
applied from a decisions file (reviewers: {', '.join(manifest['reviewers']) or 'none'}).
Rejected instances are kept in the `rejected` config with the reason and who rejected them.

Measured over all candidates (p5 / median / p95):

{chr(10).join(stats)}
"""
    (out / "README.md").write_text(text)


def write_manifest(out: Path, manifest: dict) -> None:
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def split_counts(records: list[dict], accepted: list[bool], rejected_by: list[str]) -> dict[str, dict]:
    counts: dict[str, Counter] = {}
    for r, ok, who in zip(records, accepted, rejected_by):
        c = counts.setdefault(r["split"], Counter())
        c["candidates"] += 1
        c["accepted"] += ok
        c["rejected_gate"] += (not ok) and who == "gate"
        c["rejected_review"] += (not ok) and who != "gate"
        c["accepted_over_gate"] += ok and not r["fairness"]["passed"]
    keys = ("candidates", "accepted", "rejected_gate", "rejected_review", "accepted_over_gate")
    return {split: {k: int(c[k]) for k in keys} for split, c in counts.items()}


def thresholds_dict(thresholds) -> dict:
    return asdict(thresholds)
