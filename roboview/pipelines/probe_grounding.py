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

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from roboview.benchmark.format import load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.eval.running.agents import color_words
from roboview.eval.running.results import read_episodes
from roboview.pipelines._cli import BenchmarkPath, cli_main
from roboview.tasks import make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.variation.colors import COLORS, delta_e_2000
from roboview.variation.instances import episode_seed


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


def neighbours(name: str, k: int) -> list[str]:
    """The k named colours nearest `name` in CIELAB (ΔE2000), nearest first."""
    lab = np.asarray(COLORS[name].lab)
    others = [n for n in COLORS if n != name]
    return sorted(others, key=lambda n: float(delta_e_2000(lab, np.asarray(COLORS[n].lab))))[:k]


def _best(grounder, rgb, description: str) -> float:
    found = grounder.detect(rgb, description)
    return found[0].score if found else 0.0


def run(cfg: ProbeConfig) -> dict:
    from roboview.policies.vlm.client import Endpoint
    from roboview.policies.vlm.moka import MokaConfig

    with flag_errors("--results"):
        episodes = read_episodes(cfg.results)
    if "moka_object_description" not in episodes:
        raise ValueError(
            f"{cfg.results} holds no MOKA descriptions (moka_object_description): run vlm_moka first"
        )
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path)
    instances = {item.instance.instance_id: item for items in bench.splits.values() for item in items}
    rows = episodes[episodes["moka_object_description"].notna() & episodes["repeat"].notna()]
    rows = rows[rows["moka_object_description"].map(lambda d: any(c in COLORS for c in color_words(str(d))))]
    if cfg.limit:
        rows = rows.head(cfg.limit)
    grounder = MokaConfig(
        grounding=cfg.grounding, detector_model=cfg.detector_model, endpoint=Endpoint(model="probe")
    ).grounder()
    env = make_env(cameras=(cfg.camera,), image_size=cfg.image_size)
    cases, per_color = [], {}
    try:
        for _, row in tqdm(rows.iterrows(), total=len(rows), desc="probe", unit="ep"):
            item = instances.get(row["instance_id"])
            if item is None:
                continue
            seed = episode_seed(row["context_id"], int(row["repeat"]))
            obs, _ = env.reset(seed=seed, options={"instance": item.instance})
            rgb = obs[IMAGE_KEY.format(cfg.camera)]
            text = str(row["moka_object_description"])
            word = next(c for c in color_words(text) if c in COLORS)
            base = _best(grounder, rgb, text)
            for other in neighbours(word, cfg.neighbours):
                swapped = re.sub(rf"\b{word}\b", other, text)
                rise = _best(grounder, rgb, swapped) - base
                cases.append(
                    {
                        "instance_id": row["instance_id"],
                        "repeat": int(row["repeat"]),
                        "description": text,
                        "neighbour": other,
                        "base": round(base, 4),
                        "rise": round(rise, 4),
                    }
                )
                stats = per_color.setdefault(word, [0, 0])
                stats[0] += rise > cfg.margin
                stats[1] += 1
    finally:
        env.close()
    n = len(cases)
    result = {
        "episodes": int(len({(c["instance_id"], c["repeat"]) for c in cases})),
        "cases": n,
        "margin": cfg.margin,
        "neighbours": cfg.neighbours,
        "grounding": cfg.grounding,
        "rises": int(sum(c["rise"] > cfg.margin for c in cases)),
        "share": round(sum(c["rise"] > cfg.margin for c in cases) / n, 4) if n else None,
        "per_color": {w: {"rises": a, "cases": b} for w, (a, b) in sorted(per_color.items())},
        "detail": cases,
    }
    out = Path(cfg.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "probe.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [
        "# Grounding-deviation probe",
        "",
        f"{result['episodes']} MOKA episodes whose description names a colour, {n} substitutions of that "
        f"colour by one of its {cfg.neighbours} nearest named colours (CIELAB ΔE2000); grounding backend "
        f"`{cfg.grounding}`. The neighbour grounds with more than {cfg.margin} higher confidence in "
        f"**{result['rises']} of {n} cases ({(result['share'] or 0):.2%})** (the paper: 17.78 %).",
        "",
        "| colour word | rises | cases |",
        "|---|---|---|",
    ]
    lines += [f"| {w} | {v['rises']} | {v['cases']} |" for w, v in result["per_color"].items()]
    (out / "probe.md").write_text("\n".join(lines) + "\n")
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
