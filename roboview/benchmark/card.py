"""The benchmark's dataset card (README.md with Hugging Face YAML front matter) and its statistics."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from roboview.benchmark.eval_tasks import analysis_task_ids, control_task_id, value_task_id
from roboview.variation.factors import DEFAULT_TASK, baselines
from roboview.variation.instances import split_task

if TYPE_CHECKING:
    from roboview.tasks.decomposition import Decomposition


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
    """The dataset card `out/README.md` for a built benchmark's manifest: the YAML front matter (one config per
    task, the rejected tables), the counts, how the instances were built and the perceptual fairness gate."""
    total = sum(s["accepted"] for s in manifest["splits"].values())
    text = "\n".join(
        [
            _front_matter(manifest, total),
            _counts_section(manifest, total),
            _build_section(manifest["suite"], split_task(next(iter(manifest["splits"]), ""))[0]),
            _fairness_section(manifest),
        ]
    )
    (out / "README.md").write_text(text)
    write_eval_yaml(out, manifest)


EVAL_YAML = "eval.yaml"


def write_eval_yaml(out: Path, manifest: dict) -> None:
    """`out/eval.yaml`, the file by which the Hub lists a dataset as a benchmark of any evaluation framework: its
    name, description, `evaluation_framework: roboview` and its tasks, each one leaderboard and the `task_id` a model
    repo's `.eval_results` entry names (roboview.benchmark.eval_tasks): per split the split, its control arm and, for
    a single-factor split, each value its table holds; then each task analysis's total, single changes and no-change
    view. A split's tasks carry the protocols that cover it. The layout of eval.yaml is the Hub's
    (https://huggingface.co/docs/hub/eval-results, "Eval.yaml specification": `tasks[]` items need an `id`, may
    have `config` and `split`); `metric`, `protocols` and `splits` are RoboView's own."""
    import yaml

    protocols = manifest.get("protocols") or {}
    splits = [s for s, counts in manifest["splits"].items() if counts.get("accepted")]
    tasks = []
    for split in splits:
        covered = {"protocols": sorted(n for n, p in protocols.items() if split in p.get("splits", []))}
        tasks += [
            {"id": split, "split": split, "metric": "success rate ×100"} | covered,
            {
                "id": control_task_id(split),
                "split": split,
                "metric": "success rate ×100 of the control arm (the all-baseline instance on the split's seeds)",
            }
            | covered,
            *(
                {"id": value_task_id(split, v), "split": split, "metric": f"success rate ×100 of {v}"}
                | covered
                for v in _single_factor_values(out / "data" / f"{split}.parquet")
            ),
        ]
    for design in _analyses(splits):
        variant_splits = [s for s in splits if s.removeprefix(f"{design.task}_") in design.variant_splits]
        tasks += [
            {"id": i, "metric": what, "splits": variant_splits} for i, what in analysis_task_ids(design)
        ]
    data = {
        "name": f"RoboView-Bias ({manifest['suite']['preset']})",
        "description": (
            "Visual bias of robot policies: one visual factor varied at a time over the same task contexts and "
            "seeds; success rate per split, its control arm and each value, and the spread across the factor's "
            "values beyond binomial noise."
        ),
        "evaluation_framework": "roboview",
        "version": manifest["benchmark_version"],
        "tasks": tasks,
    }
    (out / EVAL_YAML).write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True))


def _single_factor_values(table: Path) -> list[str]:
    """The values a single-factor split's table holds, in its order (none for a factorial split's)."""
    import pyarrow.parquet as pq

    rows = pq.read_table(table, columns=["factor", "value"]).to_pydict()
    if any("|" in str(f) for f in rows["factor"]):
        return []
    return list(dict.fromkeys(map(str, rows["value"])))


def _analyses(splits: list[str]) -> list[Decomposition]:
    """The analyses the splits' tasks declare (`Task.analyses`), in the splits' order, that read one of the splits (a
    design reads only its own: LIBERO-plus's noise number is not declared for a benchmark of its camera variants)."""
    from roboview.tasks import load_task

    tasks = dict.fromkeys(split_task(s)[0] for s in splits)
    designs = [design for task in tasks for design in load_task(task).analyses]
    return [d for d in designs if any(split_task(s)[0] == d.task and d.reads(s) for s in splits)]


def _front_matter(manifest: dict, total: int) -> str:
    """The Hub's YAML header: license, tags, size and the configs."""
    return f"""---
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
pretty_name: RoboView-Bias benchmark instances ({manifest["suite"]["preset"]})
configs:
{chr(10).join(_configs(manifest))}
---
"""


def _configs(manifest: dict) -> list[str]:
    """One config per task (their context columns differ; `default` holds pick_place, the paper's task), then
    one per rejected table."""
    by_task: dict[str, list[str]] = {}
    for split in manifest["splits"]:
        by_task.setdefault(split_task(split)[0], []).append(split)
    configs = []
    for task, names in sorted(by_task.items(), key=lambda kv: kv[0] != DEFAULT_TASK):
        configs += [f"- config_name: {'default' if task == DEFAULT_TASK else task}", "  data_files:"]
        for split in names:
            configs += [f"  - split: {split}", f"    path: data/{split}.parquet"]
    for name in manifest.get("rejected_tables", ["rejected"] if manifest["rejected"] else []):
        configs += [
            f"- config_name: {name}",
            "  data_files:",
            f"  - split: {name}",
            f"    path: rejected/{name}.parquet",
        ]
    return configs


def _counts_section(manifest: dict, total: int) -> str:
    """What the dataset is and how to load it, its hashes, and the counts per split."""
    table = [
        "| split | candidates | accepted | rejected (gate) | rejected (review) | accepted over gate |",
        "|---|---|---|---|---|---|",
    ]
    for name, s in manifest["splits"].items():
        table.append(
            f"| {name} | {s['candidates']} | {s['accepted']} | {s['rejected_gate']} | "
            f"{s['rejected_review']} | {s['accepted_over_gate']} |"
        )
    return f"""# RoboView-Bias benchmark instances — preset `{manifest["suite"]["preset"]}`

Frozen task instances of the RoboView-Bias benchmark: a simulated Franka Panda (MuJoCo) puts one
small object into a yellow box while exactly one visual factor varies per split. Every row is one
instance (see the RoboView docs, "Instance record"); `preview` shows the observed cameras (front, left_top, wrist)
at t = 0. Load a split with `datasets.load_dataset(PATH, split="color")`; another task's splits are its own
config: `datasets.load_dataset(PATH, "push", split="push_color")`.

**Suite hash** (SHA-256 over the accepted instance ids per split): `{manifest["suite_hash"]}`
**Benchmark version**: `{manifest["benchmark_version"]}`

## Counts

{chr(10).join(table)}

Total accepted: {total}.
"""


def _build_section(suite: dict, task: str = DEFAULT_TASK) -> str:
    """How the instances were built: the SVGF preset, its union mode and splits, the ids and seeds; the baselines
    named are those of `task`'s world (the first split's: LIBERO's and Meta-World's color `original`)."""
    base = baselines(task)
    return f"""## How the instances were built

Structured Variant-Generation Framework with the `{suite["preset"]}` preset: union mode
`{suite["union_mode"]}` for the generalization context space C_Gen (Structured Union over initial
position × shape × instruction), each visual split V_i × C_Gen(V_i) with every other visual factor
at its baseline (color {base["color"]}, camera pose {base["camera_pose"]}, Euler {base["camera_euler"]}, \
distance {base["dist_scale"]}); factorial split
color × camera_pose over colors {", ".join(suite["factorial_colors"])} in the baseline context c*.
Extra Cartesian splits: {suite["cartesian"] or "none"}. Value subsets: {suite["value_subsets"] or "none (full factor sets)"}.
`instance_id` is the first 16 hex digits of SHA-256 over the canonical JSON of the instance's
parameters; `seed` (used by env reset) is the repeat-0 seed of the instance's context (common random numbers).
"""


def _fairness_section(manifest: dict) -> str:
    """The perceptual fairness gate: stage 1's measures and pass rate, the review, the VLM screen, the quantiles."""
    stats = ["| camera | measure | p5 | median | p95 |", "|---|---|---|---|---|"]
    for cam, measures in manifest["fairness_stats"].items():
        for key, (p5, p50, p95) in measures.items():
            stats.append(f"| {cam} | {key} | {p5} | {p50} | {p95} |")
    return f"""## Perceptual fairness

Stage 1 (programmatic, at t = 0, from every observed camera): segmentation renders give the
object's and box's visible fraction (visible pixels / pixels covered when rendered unoccluded),
pixel area and whether they lie wholly in frame; CIEDE2000 compares the object's rendered color
with its nominal color and with the table. Thresholds: `{json.dumps(manifest["thresholds"])}`.
Stage-1 pass rate: {manifest["gate_pass_rate"]:.2%} of {manifest["candidates"]} candidates (the build
requires ≥ {manifest["min_pass_rate"]:.0%}). Stage 2 (review): {manifest["decisions"]} decision(s)
applied from a decisions file (reviewers: {", ".join(manifest["reviewers"]) or "none"}).
Rejected instances are kept in the `rejected` config with the reason and who rejected them.
{_screen_section(manifest)}

Measured over all candidates (p5 / median / p95):

{chr(10).join(stats)}
"""


def _screen_section(manifest: dict) -> str:
    screen = manifest.get("vlm_screen")
    if not screen:
        return ""
    t = screen["table"]
    kappa = (
        "undefined (one rater gave one answer to everything)"
        if screen["cohens_kappa"] is None
        else screen["cohens_kappa"]
    )
    return f"""
Stage 1b (VLM screen, `{screen["model"]}` at `{screen["base_url"]}`, the paper's appendix prompt on the
`front` image): {screen["pass_rate"]:.2%} "yes" over {screen["screened"]} screened ({screen["errors"]} errors); the
paper's loop target of ≥ 95 % is {"met" if screen["meets_paper_target"] else "not met"}. The screen rejects
nothing itself. Agreement with the programmatic gate: {screen["observed_agreement"]:.2%}, Cohen's κ {kappa}
(gate pass & VLM yes {t["gate_pass_vlm_yes"]}, gate pass & VLM no {t["gate_pass_vlm_no"]}, gate fail & VLM yes
{t["gate_fail_vlm_yes"]}, gate fail & VLM no {t["gate_fail_vlm_no"]}); {len(screen["disagreements"])} disagreements are
flagged in the contact sheet, and the answers are in `vlm_screen.csv` (a decisions file).
"""
