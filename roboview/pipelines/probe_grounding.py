"""The paper's grounding-deviation probe on a MOKA run: would a neighbouring colour name ground better?

    roboview-probe-grounding --results=outputs/eval/moka/episodes.parquet \\
        --benchmark.path=outputs/benchmark --output_dir=outputs/probe [--neighbours=5] [--grounding=classic]

For every MOKA episode whose object description names a colour, the episode's first frame is rendered
again (same instance, same seed: the same pixels the agent saw) and grounded twice: with the
description as the VLM wrote it, and with its colour word replaced by each of its `neighbours`
nearest named colours in CIELAB (ΔE2000, among the 141 names). A case counts when the neighbour's
grounding confidence exceeds the original's by more than `margin` (the paper: 0.03, in 17.78 % of
cases) — the VLM's own colour word was not the one the grounding model recognised best. Writes
probe.json and probe.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.benchmark.format import load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.eval.campaign.grounding_probe import ProbeSettings, colour_rows, probe, write_probe
from roboview.eval.running.results import read_episodes
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class ProbeConfig:
    # episodes.parquet of a vlm_moka evaluation.
    results: str = ""
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Folder for probe.json and probe.md.
    output_dir: str = "outputs/probe"
    # Nearest named colours (CIELAB ΔE2000) substituted for the description's colour word.
    neighbours: int = 5
    # Confidence rise that counts (the paper's threshold).
    margin: float = 0.03
    # Grounding backend, as --policy.grounding of vlm_moka: classic, owlv2 or grounding_dino.
    grounding: str = "classic"
    # transformers model id of the owlv2 / grounding_dino detector, as --policy.detector_model of vlm_moka.
    detector_model: str = "google/owlv2-base-patch16-ensemble"
    # Camera the agent looked through.
    camera: str = "front"
    # Image side (pixels) the agent saw.
    image_size: int = 224
    # Probe at most this many episodes (0: all).
    limit: int = 0

    def __post_init__(self) -> None:
        if not self.results:
            raise ValueError("--results=PATH (a vlm_moka episodes.parquet) is required")
        if self.neighbours < 1:
            raise ValueError(f"--neighbours={self.neighbours} must be at least 1")


def run(cfg: ProbeConfig) -> dict:
    from roboview.policies.vlm.client import Endpoint
    from roboview.policies.vlm.moka import MokaConfig

    with flag_errors("--results"):
        episodes = read_episodes(cfg.results)
    rows = colour_rows(episodes, cfg.results, cfg.limit)
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path)
    grounder = MokaConfig(
        grounding=cfg.grounding, detector_model=cfg.detector_model, endpoint=Endpoint(model="probe")
    ).grounder()
    settings = ProbeSettings(cfg.camera, cfg.image_size, cfg.neighbours, cfg.margin, cfg.grounding)
    result = probe(rows, bench, grounder, settings)
    write_probe(result, Path(cfg.output_dir))
    return result


def _summary(cfg: ProbeConfig, result: dict) -> None:
    share = "n/a" if result["share"] is None else f"{result['share']:.2%}"
    print(
        f"[probe_grounding] {result['rises']} of {result['cases']} substitutions ground better by > {cfg.margin} "
        f"({share}); {Path(cfg.output_dir) / 'probe.md'}"
    )


def main(args: list[str] | None = None) -> dict:
    return cli_main(ProbeConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
