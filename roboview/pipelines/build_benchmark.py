"""Build the frozen benchmark split: SVGF instances → perceptual-fairness gate → HF dataset folder.

    roboview-build-benchmark --output_dir=outputs/benchmark [--preset=paper] [--num_workers=2]

Writes `data/<split>.parquet` (one split per benchmark split), `rejected/rejected.parquet`, a
dataset card `README.md`, `benchmark.json` (machine-readable manifest with the suite hash) and
`contact_sheet/index.html` for human review. Load with `datasets.load_dataset(output_dir, split=...)`.
The build fails, after writing the contact sheet and `fairness_report.csv`, when fewer than
`--min_pass_rate` of the candidates pass the gate.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from roboview.benchmark.build import BuildResult, BuildSpec, GateFailure, build
from roboview.core.cli_errors import WorldMissing
from roboview.core.external_assets import LiberoPlusAssets
from roboview.pipelines._cli import cli_main
from roboview.policies.vlm.client import Endpoint, VLMClient
from roboview.sim.cameras import IMAGE_SIZE_MIN, check_image_size
from roboview.tasks import PRESETS, load_preset
from roboview.tasks.fairness import FairnessThresholds
from roboview.variation.instances import SuiteConfig, generate_suite

# The perceptual-fairness gate judges visibility from object pixel counts: at 64² the smallest tiny-preset
# object still covers 6 px of the front camera, at 48² 2 px, at 32² one.
GATE_IMAGE_MIN = 4 * IMAGE_SIZE_MIN


def presets_help() -> str:
    """Every registered suite preset with its instance count, as --help lists them (read from the registry, so the
    list cannot go stale)."""
    return ", ".join(f"{name} ({_count(suite)})" for name, suite in PRESETS.items()) + "."


def _count(suite: SuiteConfig) -> str:
    """A preset's instance count; a preset its world's packages must generate says how to install them instead."""
    try:
        return f"{len(generate_suite(suite)):,}"
    except ImportError as e:  # LiberoMissing / LiberoPlusMissing, its asset folder: the message says how to
        return "needs " + str(e).rpartition("install it with: ")[2]


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
    # Worker processes (spawned; one scene and renderer each), or with --ray_address renderer actors on the cluster.
    num_workers: int = 2
    # A Ray cluster (HEAD:PORT, started with `ray start --head`) whose nodes render the instances; empty: this machine.
    ray_address: str = ""
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
    # LIBERO-plus's asset folder, for its light and background presets (--liberoplus.assets=DIR).
    liberoplus: LiberoPlusAssets = field(default_factory=LiberoPlusAssets)

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


def run(cfg: BuildConfig) -> BuildResult:
    screen = (VLMClient, cfg.vlm_screen) if cfg.screen_enabled else None
    spec = BuildSpec(
        cfg.suite,
        cfg.image_size,
        cfg.fairness,
        cfg.min_pass_rate,
        cfg.num_workers,
        Path(cfg.decisions) if cfg.decisions else None,
        screen,
        cfg.ray_address or None,
    )
    result = build(spec, Path(cfg.output_dir))
    _print_summary(result.manifest)
    if "vlm_screen" in result.manifest:
        _print_screen(result.manifest["vlm_screen"])
    return result


def _print_summary(manifest: dict) -> None:
    width = max([22, *(len(s) + 2 for s in manifest["splits"])])
    print(f"{'split':<{width}}{'candidates':>11}{'accepted':>10}{'rejected':>10}{'pass':>8}")
    for split, c in manifest["splits"].items():
        rejected = c["rejected_gate"] + c["rejected_review"]
        pass_rate = c["accepted"] / c["candidates"]
        print(f"{split:<{width}}{c['candidates']:>11}{c['accepted']:>10}{rejected:>10}{pass_rate:>8.1%}")
    print(f"suite hash {manifest['suite_hash'][:16]}…  version {manifest['benchmark_version']}")
    for split, kinds in manifest.get("rejection_kinds", {}).items():
        print(f"  {split} gate failures: " + "; ".join(f"{kind} ×{n}" for kind, n in kinds.items()))
    kept = manifest.get("kept_over_gate", {})
    if any(kept.values()):
        total = sum(manifest["splits"][s]["candidates"] for s in kept)
        print(
            f"the gate would drop {sum(kept.values()):,} of the {total:,} instances of the external benchmark's own "
            f"set ({', '.join(sorted(kept))}); kept, each with its verdict (fairness.passed): reports give its number "
            "over all of them and over the fair ones"
        )


def _print_screen(screen: dict) -> None:
    kappa = "undefined" if screen["cohens_kappa"] is None else f"{screen['cohens_kappa']:.3f}"
    print(
        f"VLM screen ({screen['model']}): {screen['pass_rate']:.1%} yes over {screen['screened']} "
        f"(paper target ≥ 95 %: {'met' if screen['meets_paper_target'] else 'NOT met'}), agreement with the "
        f"gate {screen['observed_agreement']:.1%}, Cohen's κ {kappa}, {len(screen['disagreements'])} "
        f"disagreements (contact sheet; answers in vlm_screen.csv)"
    )


def _summary(cfg: BuildConfig, result: BuildResult) -> None:
    print(
        f"[build_benchmark] {result.accepted}/{result.candidates} instances in {result.output_dir} "
        f"({result.elapsed_s:.0f} s); contact sheet: {result.contact_sheet}"
    )


def main(args: list[str] | None = None) -> BuildResult:
    # WorldMissing: a world's package or assets are absent; its one line names what and how to install it.
    errors = (ValueError, GateFailure, WorldMissing)
    return cli_main(BuildConfig, run, _summary, errors, args, on_interrupt=_interrupted)


def _interrupted(cfg: BuildConfig) -> str:
    return (
        f"nothing written to {cfg.output_dir} (a build writes its folder only at the end, once every instance is "
        "rendered); rerun the same command to build it"
    )


if __name__ == "__main__":
    main()
