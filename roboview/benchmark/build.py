"""Build the frozen benchmark folder: a suite's instances rendered, judged by the fairness gate and the stage-2
decisions, and written (splits, rejected tables, contact sheet, conformance sample, checksums, manifest, card).

The folder is written into a sibling `<name>.building` folder and swapped in at the end: a build leaves either
the whole benchmark or nothing. A build whose gate pass rate is under the floor still writes its contact sheet
and `fairness_report.csv` (the offenders), then raises `GateFailure`.
"""

from __future__ import annotations

import csv
import re
import shutil
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from roboview.benchmark import conformance
from roboview.benchmark import format as bio
from roboview.benchmark.card import fairness_stats, write_card
from roboview.benchmark.contact_sheet import context_text, write_contact_sheet
from roboview.benchmark.protocols import protocols_json
from roboview.benchmark.render import InstanceRenderer
from roboview.benchmark.review import Decision, adjudicate, read_decisions
from roboview.benchmark.screen import agreement
from roboview.benchmark.screen import write_decisions as write_screen_decisions
from roboview.core.folders import folder_problem
from roboview.core.workers import WorkerPool
from roboview.tasks import DEFAULT_TASK, load_task
from roboview.tasks.fairness import FairnessThresholds
from roboview.variation.instances import SuiteConfig, generate_suite, split_name

OFFENDERS_FILE = "fairness_report.csv"
SCREEN_FILE = "vlm_screen.csv"


class GateFailure(RuntimeError):
    """Fewer candidates than required pass the perceptual-fairness gate."""


@dataclass(frozen=True)
class BuildSpec:
    """What a build renders and how it judges: the suite, the image size the gate measures, the thresholds and
    the pass-rate floor, the worker processes, the stage-2 decisions file and the optional VLM screen."""

    suite: SuiteConfig
    image_size: int
    fairness: FairnessThresholds = field(default_factory=FairnessThresholds)
    min_pass_rate: float = 0.95
    num_workers: int = 2
    decisions: Path | None = None
    # (client class, endpoint) of the stage-1b VLM screen, built in each worker; None: no screen. The endpoint's
    # `model` and `base_url` are recorded in the manifest.
    screen: tuple[Any, Any] | None = None
    # A Ray cluster (HEAD:PORT) whose nodes render the instances (roboview.benchmark.build_ray); None: local workers.
    ray_address: str | None = None


@dataclass(frozen=True)
class BuildResult:
    """What a build wrote: the folder, the candidates and those accepted, the gate's pass rate, the suite hash,
    the time it took, the contact sheet and the manifest."""

    output_dir: Path
    candidates: int
    accepted: int
    gate_pass_rate: float
    suite_hash: str
    elapsed_s: float
    contact_sheet: Path
    manifest: dict = field(default_factory=dict)  # what benchmark.json records


@dataclass(frozen=True)
class Judged:
    """The rendered candidates with their verdicts: accepted or not, and by whom rejected (gate, a reviewer)."""

    records: list[dict]
    accepted: list[bool]
    rejected_by: list[str]
    decisions: dict[str, Decision]
    # The splits kept whatever the gate says (SuiteConfig.ungated_splits, by their benchmark names).
    ungated: frozenset[str] = frozenset()

    @property
    def gate_pass_rate(self) -> float:
        """The share of candidates the stage-1 gate passed."""
        return sum(r["fairness"]["passed"] for r in self.records) / len(self.records)

    @property
    def gated(self) -> list[dict]:
        """The candidates the gate may drop (those outside the ungated splits)."""
        return [r for r in self.records if r["split"] not in self.ungated]

    @property
    def gated_pass_rate(self) -> float:
        """The share of the gated candidates the gate passed (1.0 where none is gated): what the floor judges."""
        gated = self.gated
        return sum(r["fairness"]["passed"] for r in gated) / len(gated) if gated else 1.0

    def kept_over_gate(self) -> dict[str, int]:
        """Per ungated split, how many of its candidates the gate would have dropped (all kept)."""
        out: dict[str, int] = {}
        for r in self.records:
            if r["split"] in self.ungated:
                out[r["split"]] = out.get(r["split"], 0) + (not r["fairness"]["passed"])
        return out

    def by_split(self) -> dict[str, list[dict]]:
        """The accepted records of every split, in suite order."""
        out: dict[str, list[dict]] = {}
        for r, ok in zip(self.records, self.accepted):
            if ok:
                out.setdefault(r["split"], []).append(r)
        return out

    def rejected_rows(self) -> list[dict]:
        """The rejected records, each with who rejected it."""
        return [
            {**r, "rejected_by": who}
            for r, ok, who in zip(self.records, self.accepted, self.rejected_by)
            if not ok
        ]


def check_output_dir(out: Path) -> None:
    """ValueError unless `out` is new, empty or an earlier build's folder (a build replaces it)."""
    problem = folder_problem(
        out,
        "benchmark",
        bio.MANIFEST,
        "choose a new folder or delete this one",
        label=f"--output_dir={out}",
        writing=True,
    )
    if problem:
        raise ValueError(problem)


def world_batches(instances: list, num_workers: int, most: int = 64) -> list[list[int]]:
    """Indices of `instances` in batches that each hold one world's instances (a LIBERO task's: one compiled model
    serves them all), at most `most` and at most an even share of the whole per worker, so every worker is busy."""
    groups: dict[str, list[int]] = {}
    for i, instance in enumerate(instances):
        groups.setdefault(load_task(instance.task).world_of(instance), []).append(i)
    size = max(1, min(most, -(-len(instances) // max(1, num_workers))))
    return [group[i : i + size] for group in groups.values() for i in range(0, len(group), size)]


@contextmanager
def _renderers(spec: BuildSpec, args: tuple, work) -> Iterator[Iterator[list[dict]]]:
    """The rendered batches of `work`, in order: on the Ray cluster `spec.ray_address`, else local processes."""
    if spec.ray_address:
        from roboview.benchmark.build_ray import imap_ray

        with closing(imap_ray(spec.ray_address, spec.num_workers, args, work)) as batches:
            yield batches
        return
    with WorkerPool(spec.num_workers, InstanceRenderer, args, method="records") as pool:
        yield pool.imap(work, lookahead=2 * spec.num_workers)


def render_all(spec: BuildSpec, instances: list) -> list[dict]:
    """Every instance's record (cameras, fairness, preview), in suite order: the worker pool renders one world's
    instances per call (`world_batches`), so a world is built once per batch, not once per instance."""
    args = (spec.image_size, spec.fairness, DEFAULT_TASK, spec.screen)
    bar = tqdm(total=len(instances), desc="build", unit="inst", dynamic_ncols=True)
    batches = world_batches(instances, spec.num_workers)
    records: list[dict | None] = [None] * len(instances)
    passed = done = 0
    work = ([instances[i] for i in batch] for batch in batches)
    try:
        with _renderers(spec, args, work) as rendered_batches:
            for batch, rendered in zip(batches, rendered_batches):
                for i, record in zip(batch, rendered):
                    records[i] = record
                    passed += record["fairness"]["passed"]
                done += len(batch)
                bar.update(len(batch))
                bar.set_postfix(passed=f"{passed / done:.1%}")
    finally:  # also on Ctrl-C: the bar ends its line before the closing message
        bar.close()
    return records  # type: ignore[return-value]


def build(spec: BuildSpec, output_dir: Path) -> BuildResult:
    """Render, judge and write the benchmark to `output_dir`; GateFailure (after writing the offenders) when too
    few candidates pass the gate. Input errors (the folder, the decisions file) raise ValueError before work."""
    check_output_dir(output_dir)
    instances = generate_suite(spec.suite)
    decisions = read_decisions(spec.decisions, {i.instance_id for i in instances}) if spec.decisions else {}
    t0 = time.perf_counter()
    records = render_all(spec, instances)
    ungated = ungated_split_names(spec.suite)
    verdicts = [adjudicate(r, decisions.get(r["instance_id"]), r["split"] in ungated) for r in records]
    judged = Judged(records, [ok for ok, _ in verdicts], [who for _, who in verdicts], decisions, ungated)
    # Write into a sibling temp folder and swap it in: never a half-written benchmark.
    tmp = output_dir.with_name(output_dir.name + ".building")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    sheet = write_contact_sheet(tmp, records, judged.accepted, judged.rejected_by)
    manifest = _write_folder(spec, judged, tmp)
    shutil.rmtree(output_dir, ignore_errors=True)
    tmp.rename(output_dir)
    sheet = output_dir / sheet.relative_to(tmp)
    if manifest["status"] != bio.BUILT:
        raise GateFailure(
            f"only {judged.gated_pass_rate:.1%} of {len(judged.gated)} gated candidates pass the fairness gate "
            f"(need {spec.min_pass_rate:.0%}); offenders in {output_dir / OFFENDERS_FILE}, "
            f"previews in {sheet}. Fix the scene (camera aims, positions), not the threshold."
        )
    return BuildResult(
        output_dir,
        len(records),
        sum(judged.accepted),
        judged.gate_pass_rate,
        manifest["suite_hash"],
        time.perf_counter() - t0,
        sheet,
        manifest,
    )


def _write_folder(spec: BuildSpec, judged: Judged, tmp: Path) -> dict:
    """Write the screen's answers, the tables (or the offenders of a failed gate), the integrity files, the
    manifest and the card into `tmp`; the manifest."""
    screen = _screen(spec, judged.records, tmp)
    by_split, rejected = judged.by_split(), judged.rejected_rows()
    passed = judged.gated_pass_rate >= spec.min_pass_rate
    content, reference, stack, protocols = {}, None, None, None
    if passed:
        protocols = protocols_json([s for s, rows in by_split.items() if rows], spec.suite.preset)
        _write_tables(tmp, by_split, rejected)
        # What was written, as it reads back: the conformance sample, then every cell's checksum.
        written = {split: bio.read_rows(tmp / "data" / f"{split}.parquet") for split in by_split}
        stack = conformance.write_reference(tmp, written, spec.image_size)
        content = bio.write_checksums(tmp)
        reference = bio.reference_hash(tmp)
    else:
        _write_offenders(tmp, judged.records)
    manifest = {
        "status": bio.BUILT if passed else bio.FAILED_GATE,
        "suite": suite_record(spec.suite),
        "image_size": spec.image_size,
        "thresholds": asdict(spec.fairness),
        "candidates": len(judged.records),
        "gate_pass_rate": judged.gate_pass_rate,
        "min_pass_rate": spec.min_pass_rate,
        **(
            {
                "ungated_splits": sorted(judged.ungated),
                "gated_pass_rate": judged.gated_pass_rate,
                "kept_over_gate": judged.kept_over_gate(),
            }
            if judged.ungated
            else {}
        ),
        "splits": bio.split_counts(judged.records, judged.accepted, judged.rejected_by),
        "rejected": len(rejected),
        **({"rejected_tables": sorted(map(rejected_table, _by_task(rejected)))} if rejected else {}),
        "decisions": len(judged.decisions),
        "reviewers": sorted({d.reviewer for d in judged.decisions.values()}),
        "suite_hash": bio.suite_hash(by_split),
        "content": content,
        "stack": stack,
        **({"protocols": protocols} if protocols else {}),
        "benchmark_version": bio.benchmark_version(spec.suite.preset, content, reference, protocols),
        "fairness_stats": fairness_stats(judged.records),
        "rejection_kinds": rejection_kinds(judged.records),
        **({"vlm_screen": screen} if screen is not None else {}),
    }
    bio.write_manifest(tmp, manifest)
    if passed:
        write_card(tmp, manifest)
    return manifest


def rejection_kinds(records: list[dict]) -> dict[str, dict[str, int]]:
    """Per split, how many candidates the gate failed for each kind of reason (a reason's words without its figures:
    "agentview: object not wholly in frame", "agentview: object visible < …"); a candidate counts under each of its
    reasons. Splits the gate passed whole are left out."""
    out: dict[str, Counter] = {}
    for r in records:
        if r["fairness"]["passed"]:
            continue
        kinds = {reason_kind(part) for part in r["fairness"]["reject_reason"].split("; ")}
        out.setdefault(r["split"], Counter()).update(kinds)
    return {split: dict(c.most_common()) for split, c in out.items()}


def reason_kind(reason: str) -> str:
    """A gate reason without its figures: "agentview: object visible 0.45 < 0.49 (…)" → "agentview: object visible"."""
    words = re.sub(r"\s*[<>].*$", "", reason)  # the comparison and what follows it
    return re.sub(r"\s[-\d.]+(?:\s*px)?(?=\s|$)", "", words).strip()  # the measured figure


def ungated_split_names(suite: SuiteConfig) -> frozenset[str]:
    """The benchmark names of the suite's ungated splits, for each of its tasks."""
    return frozenset(split_name(s, task) for s in suite.ungated_splits for task in suite.tasks)


def suite_record(suite: SuiteConfig) -> dict:
    """The suite as the manifest records it."""
    return {
        "preset": suite.preset,
        "union_mode": suite.union_mode,
        "splits": list(suite.splits),
        "factorial_colors": list(suite.factorial_colors),
        "cartesian": [list(c) for c in suite.cartesian],
        "value_subsets": {k: list(v) for k, v in suite.value_subsets},
        **({"ungated_splits": list(suite.ungated_splits)} if suite.ungated_splits else {}),
    }


def _screen(spec: BuildSpec, records: list[dict], out: Path) -> dict | None:
    """The VLM screen's agreement with the gate (its answers written to vlm_screen.csv); None without a screen."""
    if spec.screen is None:
        return None
    endpoint = spec.screen[1]
    write_screen_decisions(out / SCREEN_FILE, records, f"vlm:{endpoint.model}")
    return agreement(records) | {"model": endpoint.model, "base_url": endpoint.base_url}


def _write_tables(out: Path, by_split: dict[str, list[dict]], rejected: list[dict]) -> None:
    for split, rows in by_split.items():
        bio.write_split(rows, out / "data" / f"{split}.parquet")
    for task, rows in _by_task(rejected).items():  # one table per task: their columns differ
        bio.write_split(rows, out / "rejected" / f"{rejected_table(task)}.parquet", rejected=True)


def rejected_table(task: str) -> str:
    """The rejected table's name (and card config) of a task: `rejected` for pick_place, `<task>_rejected`."""
    return "rejected" if task == DEFAULT_TASK else f"{task}_rejected"


def _by_task(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for row in rows:
        out.setdefault(row.get("task", DEFAULT_TASK), []).append(row)
    return out


def _write_offenders(out: Path, records: list[dict]) -> None:
    with (out / OFFENDERS_FILE).open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["instance_id", "task", "split", "value", "context", "reject_reason"])
        for r in records:
            if not r["fairness"]["passed"]:
                writer.writerow(
                    [
                        r["instance_id"],
                        r.get("task", DEFAULT_TASK),
                        r["split"],
                        r["value"],
                        context_text(r),
                        r["fairness"]["reject_reason"],
                    ]
                )
