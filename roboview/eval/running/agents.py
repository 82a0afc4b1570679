"""What the VLM-driven agents did, from their own episode columns: usage, descriptions, SGL.

- **VLM usage** (`vlm_*` columns, `roboview.policies.vlm.client`): requests, cache hits, prompt and completion
  tokens and seconds waiting, summed per policy and per episode.
- **Object descriptions** (MOKA, `moka_object_description`): the paper's case study — how often each
  head noun is used (its figure: `cube` 30.0 %, `cylinder` 23.9 %, `object` 22.4 %) and how often a
  description names no colour at all.
- **SGL** (`sgl_*` columns): how often the instruction was ambiguous and which attribute resolved it.
"""

from __future__ import annotations

import re
from collections import Counter
from typing import Any

import pandas as pd

from roboview.variation.colors import CATEGORIES, COLORS

VLM_COLUMNS = (
    "vlm_requests",
    "vlm_cache_hits",
    "vlm_prompt_tokens",
    "vlm_completion_tokens",
    "vlm_latency_s",
)
COLOR_WORDS = frozenset([*COLORS, *CATEGORIES, "grey"])


def color_words(description: str) -> list[str]:
    """Colour names in a description ("dark red" counts as darkred)."""
    words = re.findall(r"[a-z]+", description.lower())
    found, skip = [], False
    for i, word in enumerate(words):
        if skip:
            skip = False
            continue
        if i + 1 < len(words) and word + words[i + 1] in COLORS:
            found.append(word + words[i + 1])
            skip = True
        elif word in COLOR_WORDS:
            found.append(word)
    return found


def head_noun(description: str) -> str:
    words = re.findall(r"[a-z]+", description.lower())
    return words[-1] if words else ""


def describe_agents(episodes: pd.DataFrame) -> dict[str, Any]:
    """Per policy: VLM usage sums, the descriptions' word statistics, SGL outcomes (only what is present)."""
    out: dict[str, Any] = {}
    for policy, rows in episodes.groupby("policy", sort=True):
        entry: dict[str, Any] = {}
        present = [c for c in VLM_COLUMNS if c in rows and rows[c].notna().any()]
        if present:
            sums = {c.removeprefix("vlm_"): round(float(rows[c].fillna(0).sum()), 3) for c in present}
            entry["vlm"] = {
                **sums,
                "episodes": len(rows),
                "requests_per_episode": round(sums.get("requests", 0) / len(rows), 3),
            }
        if "moka_object_description" in rows and rows["moka_object_description"].notna().any():
            texts = rows["moka_object_description"].dropna().astype(str)
            nouns = Counter(head_noun(t) for t in texts)
            colors = Counter(c for t in texts for c in color_words(t))
            entry["descriptions"] = {
                "n": len(texts),
                "head_nouns": {k: round(v / len(texts), 4) for k, v in nouns.most_common()},
                "color_words": {k: round(v / len(texts), 4) for k, v in colors.most_common()},
                "without_color": round(float(sum(not color_words(t) for t in texts) / len(texts)), 4),
            }
        if "sgl_instruction" in rows and rows["sgl_instruction"].notna().any():
            grounded = rows[rows["sgl_instruction"].notna()]
            attributes = Counter(a for a in grounded["sgl_attribute"].fillna("") if a)
            entry["sgl"] = {
                "n": len(grounded),
                "ambiguous": round(float(grounded["sgl_ambiguous"].astype(bool).mean()), 4),
                "attributes": {k: round(v / len(grounded), 4) for k, v in attributes.most_common()},
            }
        if entry:
            out[str(policy)] = entry
    return out


def agents_markdown(agents: dict[str, Any]) -> list[str]:
    if not agents:
        return []
    lines = ["## VLM agents", ""]
    usage = {p: a["vlm"] for p, a in agents.items() if "vlm" in a}
    if usage:
        lines += [
            "| policy | episodes | requests | per episode | cache hits | prompt tokens | completion tokens | "
            "seconds waiting |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for p, u in usage.items():
            lines.append(
                f"| {p} | {u['episodes']} | {u.get('requests', 0):g} | {u['requests_per_episode']:g} | "
                f"{u.get('cache_hits', 0):g} | {u.get('prompt_tokens', 0):g} | {u.get('completion_tokens', 0):g} | "
                f"{u.get('latency_s', 0):.1f} |"
            )
        lines.append("")
    for p, a in agents.items():
        d = a.get("descriptions")
        if d:
            nouns = ", ".join(f"`{k}` {v:.1%}" for k, v in list(d["head_nouns"].items())[:6])
            colors = ", ".join(f"`{k}` {v:.1%}" for k, v in list(d["color_words"].items())[:8])
            lines += [
                f"- {p}: object descriptions ({d['n']}) end in {nouns}; colour words {colors or 'none'}; "
                f"{d['without_color']:.1%} name no colour."
            ]
        s = a.get("sgl")
        if s:
            attrs = ", ".join(f"{k} {v:.1%}" for k, v in s["attributes"].items()) or "none"
            lines += [
                f"- {p}: SGL found {s['ambiguous']:.1%} of {s['n']} instructions ambiguous; attribute chosen: {attrs}."
            ]
    return [*lines, ""]
