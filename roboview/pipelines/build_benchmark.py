"""Build the frozen benchmark split: SVGF instances → perceptual-fairness gate → HF dataset folder.

    roboview-build-benchmark --output_dir=outputs/benchmark [--preset=paper] [--num_workers=2]

Writes `data/<split>.parquet` (one split per benchmark split), `rejected/rejected.parquet`, a
dataset card `README.md`, `benchmark.json` (machine-readable manifest with the suite hash) and
`contact_sheet/index.html` for human review. Load with `datasets.load_dataset(output_dir, split=...)`.
The build fails, after writing the contact sheet and `fairness_report.csv`, when fewer than
`--min_pass_rate` of the candidates pass the gate.
"""

from __future__ import annotations

import csv
import logging
import shutil
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from roboview.benchmark import conformance
from roboview.benchmark import format as bio
from roboview.benchmark.card import fairness_stats, write_card
from roboview.benchmark.contact_sheet import context_text, write_contact_sheet
from roboview.benchmark.fairness import FairnessThresholds
from roboview.benchmark.render import InstanceRenderer
from roboview.benchmark.review import adjudicate, read_decisions
from roboview.benchmark.screen import agreement
from roboview.benchmark.screen import write_decisions as write_screen_decisions
from roboview.core.folders import folder_problem
from roboview.core.workers import WorkerPool
from roboview.pipelines._cli import cli_main
from roboview.policies.vlm.client import Endpoint, VLMClient
from roboview.sim.cameras import IMAGE_SIZE_MIN, check_image_size
from roboview.tasks import DEFAULT_TASK, PRESETS, load_preset
from roboview.variation.instances import SuiteConfig, generate_suite

log = logging.getLogger(__name__)

# The perceptual-fairness gate judges visibility from object pixel counts: at 64² the smallest tiny-preset
# object still covers 6 px of the front camera, at 48² 2 px, at 32² one.
GATE_IMAGE_MIN = 4 * IMAGE_SIZE_MIN


def presets_help() -> str:
    """Every registered suite preset with its instance count, as --help lists them (read from the registry, so the
    list cannot go stale)."""
    return ", ".join(f"{name} ({len(generate_suite(suite)):,})" for name, suite in PRESETS.items()) + "."


@dataclass
class BuildConfig:
    # Folder to write the Hugging Face dataset into (new, empty, or an earlier build's output).
    output_dir: str = "outputs/benchmark"
    # Suite preset (tiny and tiny_extended are for demos and tests); the presets and their instance counts:
    preset: str = "paper"
    # Override the preset's Structured Union mode: per_subspace or dedupe.
    union_mode: str | None = None
    # Override the colors crossed with the 21 orbital poses in color_x_camera_pose.
    factorial_colors: list[str] | None = None
    # Add one full Cartesian-product split over these factors (e.g. [color,shape]).
    cartesian: list[str] | None = None
    # Worker processes (spawned; one scene and renderer each).
    num_workers: int = 2
    # Side of the rendered camera images the gate measures and previews come from (pixels).
    image_size: int = 224
    # Stage-2 decisions CSV (instance_id, verdict, reviewer, note) from reviewing the contact sheet.
    decisions: str | None = None
    # The build fails when fewer than this share of candidates pass the stage-1 gate (paper: 0.95, i.e. 95 percent).
    min_pass_rate: float = 0.95
    # Stage-1 thresholds.
    fairness: FairnessThresholds = field(default_factory=FairnessThresholds)
    # Stage 1b, optional: the paper's VLM fairness screen over every candidate's front image, on this endpoint
    # (--vlm_screen.model=gpt-4o --vlm_screen.base_url=...; no model: no screen), reported with its agreement
    # with the gate; it rejects nothing itself (see vlm_screen.csv). A rebuild asks nothing twice (the cache).
    vlm_screen: Endpoint = field(default_factory=Endpoint)

    # --help appends the registry's presets to the description of --preset.
    help_details = {"preset": presets_help}

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ValueError(f"unknown --preset={self.preset!r}; allowed: {', '.join(PRESETS)}")
        if self.num_workers <= 0:
            raise ValueError(f"--num_workers={self.num_workers} must be a positive count")
        check_image_size(
            self.image_size,
            "--image_size",
            GATE_IMAGE_MIN,
            f"the fairness gate counts object pixels; below {GATE_IMAGE_MIN} px the smallest "
            "object covers 2 px or fewer of the front camera",
        )
        if not 0.0 < self.min_pass_rate <= 1.0:
            raise ValueError(f"--min_pass_rate={self.min_pass_rate} must lie in (0, 1]")
        self.suite  # noqa: B018  (validates union mode, colors and factor names now, before any work)
        if self.screen_enabled:
            self.vlm_screen.validate("--vlm_screen.")

    @property
    def screen_enabled(self) -> bool:
        return bool(self.vlm_screen.model)

    @property
    def suite(self) -> SuiteConfig:
        suite = load_preset(self.preset)
        if self.union_mode is not None:
            suite = replace(suite, union_mode=self.union_mode)
        if self.factorial_colors is not None:
            suite = replace(suite, factorial_colors=tuple(self.factorial_colors))
        if self.cartesian:
            suite = replace(suite, cartesian=(*suite.cartesian, tuple(self.cartesian)))
        return suite


@dataclass(frozen=True)
class BuildResult:
    output_dir: Path
    candidates: int
    accepted: int
    gate_pass_rate: float
    suite_hash: str
    elapsed_s: float
    contact_sheet: Path


def _check_output_dir(out: Path) -> None:
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


def _render_all(cfg: BuildConfig, instances: list) -> list[dict]:
    screen = (VLMClient, cfg.vlm_screen) if cfg.screen_enabled else None
    args = (cfg.image_size, cfg.fairness, DEFAULT_TASK, screen)
    bar = tqdm(total=len(instances), desc="build", unit="inst", dynamic_ncols=True)
    records, passed = [], 0
    try:
        with WorkerPool(cfg.num_workers, InstanceRenderer, args, method="record") as pool:
            for record in pool.imap(instances, lookahead=8 * cfg.num_workers):
                records.append(record)
                passed += record["fairness"]["passed"]
                bar.update(1)
                bar.set_postfix(passed=f"{passed / len(records):.1%}")
    finally:  # also on Ctrl-C: the bar ends its line before the closing message
        bar.close()
    return records


def run(cfg: BuildConfig) -> BuildResult:
    out = Path(cfg.output_dir)
    _check_output_dir(out)
    suite = cfg.suite
    instances = generate_suite(suite)
    decisions = (
        read_decisions(Path(cfg.decisions), {i.instance_id for i in instances}) if cfg.decisions else {}
    )
    t0 = time.perf_counter()
    records = _render_all(cfg, instances)
    verdicts = [adjudicate(r, decisions.get(r["instance_id"])) for r in records]
    accepted = [ok for ok, _ in verdicts]
    rejected_by = [who for _, who in verdicts]
    gate_rate = sum(r["fairness"]["passed"] for r in records) / len(records)

    # Write into a sibling temp folder and swap it in: never a half-written benchmark.
    tmp = out.with_name(out.name + ".building")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    sheet = write_contact_sheet(tmp, records, accepted, rejected_by)
    screen = agreement(records) if cfg.screen_enabled else None
    if screen is not None:
        screen |= {"model": cfg.vlm_screen.model, "base_url": cfg.vlm_screen.base_url}
        write_screen_decisions(tmp / "vlm_screen.csv", records, f"vlm:{cfg.vlm_screen.model}")
    by_split: dict[str, list[dict]] = {}
    rejected_rows = []
    for r, ok, who in zip(records, accepted, rejected_by):
        if ok:
            by_split.setdefault(r["split"], []).append(r)
        else:
            rejected_rows.append({**r, "rejected_by": who})
    if gate_rate < cfg.min_pass_rate:
        _write_offenders(tmp, records)
    else:
        for split, rows in by_split.items():
            bio.write_split(rows, tmp / "data" / f"{split}.parquet")
        for task, rows in _by_task(rejected_rows).items():  # one table per task: their columns differ
            bio.write_split(rows, tmp / "rejected" / f"{_rejected_table(task)}.parquet", rejected=True)
    digest = bio.suite_hash(by_split)
    content, reference, stack = {}, None, None
    if gate_rate >= cfg.min_pass_rate:
        # What was written, as it reads back: the conformance sample, then every cell's checksum.
        written = {split: bio.read_rows(tmp / "data" / f"{split}.parquet") for split in by_split}
        stack = conformance.write_reference(tmp, written, cfg.image_size)
        content = bio.write_checksums(tmp)
        reference = bio.reference_hash(tmp)
    manifest = {
        "status": "ok" if gate_rate >= cfg.min_pass_rate else "failed_gate",
        "suite": {
            "preset": suite.preset,
            "union_mode": suite.union_mode,
            "splits": list(suite.splits),
            "factorial_colors": list(suite.factorial_colors),
            "cartesian": [list(c) for c in suite.cartesian],
            "value_subsets": {k: list(v) for k, v in suite.value_subsets},
        },
        "image_size": cfg.image_size,
        "thresholds": asdict(cfg.fairness),
        "candidates": len(records),
        "gate_pass_rate": gate_rate,
        "min_pass_rate": cfg.min_pass_rate,
        "splits": bio.split_counts(records, accepted, rejected_by),
        "rejected": len(rejected_rows),
        **(
            {"rejected_tables": sorted(map(_rejected_table, _by_task(rejected_rows)))}
            if rejected_rows
            else {}
        ),
        "decisions": len(decisions),
        "reviewers": sorted({d.reviewer for d in decisions.values()}),
        "suite_hash": digest,
        "content": content,
        "stack": stack,
        "benchmark_version": bio.benchmark_version(suite.preset, content, reference),
        "fairness_stats": fairness_stats(records),
        **({"vlm_screen": screen} if screen is not None else {}),
    }
    bio.write_manifest(tmp, manifest)
    if manifest["status"] == "ok":
        write_card(tmp, manifest)
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)
    sheet = out / sheet.relative_to(tmp)
    if manifest["status"] != "ok":
        raise GateFailure(
            f"only {gate_rate:.1%} of {len(records)} candidates pass the fairness gate "
            f"(need {cfg.min_pass_rate:.0%}); offenders in {out / 'fairness_report.csv'}, "
            f"previews in {sheet}. Fix the scene (camera aims, positions), not the threshold."
        )
    _print_summary(manifest)
    if screen is not None:
        kappa = "undefined" if screen["cohens_kappa"] is None else f"{screen['cohens_kappa']:.3f}"
        print(
            f"VLM screen ({screen['model']}): {screen['pass_rate']:.1%} yes over {screen['screened']} "
            f"(paper target ≥ 95 %: {'met' if screen['meets_paper_target'] else 'NOT met'}), agreement with the "
            f"gate {screen['observed_agreement']:.1%}, Cohen's κ {kappa}, {len(screen['disagreements'])} "
            f"disagreements (contact sheet; answers in vlm_screen.csv)"
        )
    return BuildResult(out, len(records), sum(accepted), gate_rate, digest, time.perf_counter() - t0, sheet)


def _rejected_table(task: str) -> str:
    """The rejected table's name (and card config) of a task: `rejected` for pick_place, `<task>_rejected`."""
    return "rejected" if task == DEFAULT_TASK else f"{task}_rejected"


def _by_task(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for row in rows:
        out.setdefault(row.get("task", DEFAULT_TASK), []).append(row)
    return out


class GateFailure(RuntimeError):
    """Fewer candidates than required pass the perceptual-fairness gate."""


def _write_offenders(out: Path, records: list[dict]) -> None:
    with (out / "fairness_report.csv").open("w", newline="") as f:
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


def _print_summary(manifest: dict) -> None:
    print(f"{'split':<22}{'candidates':>11}{'accepted':>10}{'rejected':>10}{'pass':>8}")
    for split, c in manifest["splits"].items():
        rejected = c["rejected_gate"] + c["rejected_review"]
        print(
            f"{split:<22}{c['candidates']:>11}{c['accepted']:>10}{rejected:>10}{c['accepted'] / c['candidates']:>8.1%}"
        )
    print(f"suite hash {manifest['suite_hash'][:16]}…  version {manifest['benchmark_version']}")


def _summary(cfg: BuildConfig, result: BuildResult) -> None:
    print(
        f"[build_benchmark] {result.accepted}/{result.candidates} instances in {result.output_dir} "
        f"({result.elapsed_s:.0f} s); contact sheet: {result.contact_sheet}"
    )


def main(args: list[str] | None = None) -> BuildResult:
    return cli_main(BuildConfig, run, _summary, (ValueError, GateFailure), args, on_interrupt=_interrupted)


def _interrupted(cfg: BuildConfig) -> str:
    return (
        f"nothing written to {cfg.output_dir} (a build writes its folder only at the end, once every instance is "
        "rendered); rerun the same command to build it"
    )


if __name__ == "__main__":
    main()
