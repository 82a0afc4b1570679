"""The paper's grounding-deviation probe on a MOKA run: would a neighbouring colour name ground better?

Every MOKA episode whose object description names a colour has its first frame rendered again (same instance,
same seed: the pixels the agent saw) and grounded with the description as the VLM wrote it, then with its colour
word replaced by each of its nearest named colours in CIELAB (ΔE2000). A case counts when the neighbour's
grounding confidence exceeds the original's by more than the margin.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from roboview.benchmark.format import Benchmark
from roboview.eval.running.agents import color_words
from roboview.tasks import make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.variation.colors import COLORS, delta_e_2000
from roboview.variation.instances import episode_seed

DESCRIPTION = "moka_object_description"


@dataclass(frozen=True)
class ProbeSettings:
    """How the probe looks and counts: the camera and image side the agent saw, the neighbouring colour names tried
    per description, the confidence rise that counts, and the grounding backend's name (for the record)."""

    camera: str = "front"
    image_size: int = 224
    neighbours: int = 5
    margin: float = 0.03
    grounding: str = "classic"


def neighbours(name: str, k: int) -> list[str]:
    """The k named colours nearest `name` in CIELAB (ΔE2000), nearest first."""
    lab = np.asarray(COLORS[name].lab)
    others = [n for n in COLORS if n != name]
    return sorted(others, key=lambda n: float(delta_e_2000(lab, np.asarray(COLORS[n].lab))))[:k]


def colour_rows(episodes: pd.DataFrame, results: str, limit: int = 0) -> pd.DataFrame:
    """The episodes (at most `limit`; 0: all) whose MOKA description names a colour; ValueError for results (read
    from `results`) without MOKA descriptions."""
    if DESCRIPTION not in episodes:
        raise ValueError(f"{results} holds no MOKA descriptions ({DESCRIPTION}): run vlm_moka first")
    rows = episodes[episodes[DESCRIPTION].notna() & episodes["repeat"].notna()]
    rows = rows[rows[DESCRIPTION].map(lambda d: any(c in COLORS for c in color_words(str(d))))]
    return rows.head(limit) if limit else rows


def _best(grounder: Any, rgb: np.ndarray, description: str) -> float:
    found = grounder.detect(rgb, description)
    return found[0].score if found else 0.0


def substitutions(
    grounder: Any, rgb: np.ndarray, text: str, k: int
) -> tuple[str, float, list[tuple[str, float]]]:
    """(the description's colour word, its grounding confidence, (neighbour, confidence rise) for each of its `k`
    nearest named colours substituted for it)."""
    word = next(c for c in color_words(text) if c in COLORS)
    base = _best(grounder, rgb, text)
    rises = [
        (other, _best(grounder, rgb, re.sub(rf"\b{word}\b", other, text)) - base)
        for other in neighbours(word, k)
    ]
    return word, base, rises


def probe(rows: pd.DataFrame, bench: Benchmark, grounder: Any, settings: ProbeSettings) -> dict:
    """Re-render each row's first frame and reground it with neighbouring colour names; the result: counts, the
    share of rises over the margin, per colour word, and every case."""
    instances = {item.instance.instance_id: item for items in bench.splits.values() for item in items}
    env = make_env(cameras=(settings.camera,), image_size=settings.image_size)
    cases, per_color = [], {}
    try:
        for _, row in tqdm(rows.iterrows(), total=len(rows), desc="probe", unit="ep"):
            item = instances.get(row["instance_id"])
            if item is None:
                continue
            seed = episode_seed(row["context_id"], int(row["repeat"]))
            obs, _ = env.reset(seed=seed, options={"instance": item.episode(int(row["repeat"]))})
            text = str(row[DESCRIPTION])
            word, base, rises = substitutions(
                grounder, obs[IMAGE_KEY.format(settings.camera)], text, settings.neighbours
            )
            for other, rise in rises:
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
                stats[0] += rise > settings.margin
                stats[1] += 1
    finally:
        env.close()
    return _result(cases, per_color, settings)


def _result(cases: list[dict], per_color: dict[str, list[int]], settings: ProbeSettings) -> dict:
    n, margin = len(cases), settings.margin
    return {
        "episodes": int(len({(c["instance_id"], c["repeat"]) for c in cases})),
        "cases": n,
        "margin": margin,
        "neighbours": settings.neighbours,
        "grounding": settings.grounding,
        "rises": int(sum(c["rise"] > margin for c in cases)),
        "share": round(sum(c["rise"] > margin for c in cases) / n, 4) if n else None,
        "per_color": {w: {"rises": a, "cases": b} for w, (a, b) in sorted(per_color.items())},
        "detail": cases,
    }


def write_probe(result: dict, out: Path) -> None:
    """probe.json (the result) and probe.md (the share, per colour word) in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "probe.json").write_text(json.dumps(result, indent=2) + "\n")
    n = result["cases"]
    lines = [
        "# Grounding-deviation probe",
        "",
        f"{result['episodes']} MOKA episodes whose description names a colour, {n} substitutions of that "
        f"colour by one of its {result['neighbours']} nearest named colours (CIELAB ΔE2000); grounding backend "
        f"`{result['grounding']}`. The neighbour grounds with more than {result['margin']} higher confidence in "
        f"**{result['rises']} of {n} cases ({(result['share'] or 0):.2%})** (the paper: 17.78 %).",
        "",
        "| colour word | rises | cases |",
        "|---|---|---|",
    ]
    lines += [f"| {w} | {v['rises']} | {v['cases']} |" for w, v in result["per_color"].items()]
    (out / "probe.md").write_text("\n".join(lines) + "\n")
