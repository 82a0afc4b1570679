"""The isolation certificate: proof, episode by episode, that only the factor changed.

A split compares the values of a factor within blocks: every value of one (context, repeat) runs with
the same episode seed (common random numbers). That comparison isolates the factor only if nothing
else differs inside a block. Each episode therefore records, right after its env reset, a short hash
of each thing that must not change across the values of its block (`isolation` column, JSON):

    instruction       the instruction text the policy is given
    robot             the initial robot state (7 joint positions + gripper)
    object_xy         the object's initial position on the table (x, y), after jitter
    object_height     its initial height
    object_rotation   its initial orientation
    seed              the episode seed
    context           every factor's value except those the split varies
    camera:<name>     each camera's calibration at t = 0 (position, orientation, field of view)
    image:<name>      the corruption a camera's frames go through after rendering (LIBERO-plus's sensor noise),
                      recorded only for a camera that has one
    card              the scene_text card's pose and size, where the scene holds one (its texture is the factor)

`verify` groups a split's episodes into blocks (context_id, repeat) and checks every component is the
same for every value, except what the split's varied factors declare they change (`Factor.alters`:
the camera factors move `front` and `left_top`; `object_size` changes the object's height). A block that
disagrees is a violation: the report lists it and the statistics leave it out, with a warning. Floats
are hashed at 1e-9 resolution (physics and rendering are deterministic; this only absorbs printing).

A context factor set away from its baseline may declare what then changes *with* the split's values
(`liberoplus_instruction=liberoplus` tells the policy an instruction that names the view: `instruction`).
The certificate lets it differ and names it. Each split's `changes` lists everything its values change
(its varied factors, then such components). A split is `isolated` only when that is one factor: a
two-factor split (LIBERO-plus's azimuth with elevation) or a changed instruction is labelled as such.
"""

from __future__ import annotations

import hashlib
import json
import logging
from typing import Any

import numpy as np
import pandas as pd

from roboview.variation.factors import load_factor

log = logging.getLogger(__name__)

COLUMN = "isolation"
COMPONENTS = ("instruction", "robot", "object_xy", "object_height", "object_rotation", "seed", "context")
BLOCK = ("context_id", "repeat")


def _digest(value: Any) -> str:
    if isinstance(value, np.ndarray | list | tuple):
        value = [round(float(x), 9) + 0.0 for x in np.ravel(value)]  # + 0.0: -0.0 and 0.0 hash alike
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


def components(env, seed: int) -> dict[str, str]:
    """Hashes of everything an episode's block must share, read from an env just reset for it."""
    instance = env.instance
    position, quat = env.object_pose()
    quat = np.asarray(quat) * (1 if quat[0] >= 0 else -1)  # q and -q are one orientation
    out = {
        "instruction": _digest(env.instruction),
        "robot": _digest(env.state()),
        "object_xy": _digest(position[:2]),
        "object_height": _digest(position[2:]),
        "object_rotation": _digest(quat),
        "seed": _digest(int(seed)),
        "context": _digest({k: v for k, v in instance.factors if k not in instance.varied}),
    }
    # Only a scene compiled with the card has one: every other episode's record stays as it was.
    card = env.text_card() if hasattr(env, "text_card") else None
    if card is not None:
        out["card"] = _digest(card.geometry())
    for name in sorted(env.camera_ids()):
        pose = env.camera_pose(name)
        out[f"camera:{name}"] = _digest([*pose.pos, *pose.quat, pose.fovy])
    for name, corruption in sorted(env.image_filters().items()):
        out[f"image:{name}"] = _digest(corruption)
    return out


def record(env, seed: int) -> str:
    """The `isolation` column of an episode's row."""
    return json.dumps(components(env, seed), sort_keys=True)


def allowed_to_differ(varied: tuple[str, ...]) -> set[str]:
    """Components the split's varied factors may change across their values."""
    out: set[str] = set()
    for name in varied:
        out |= set(load_factor(name).alters)
    return out


def verify(episodes: pd.DataFrame) -> dict[str, dict[str, Any]]:
    """Per split: blocks checked, blocks verified identical, and each violation (block, components, values).

    A split whose rows carry no certificate (results converted from lerobot-eval, or written before the
    column existed) reports `recorded: false` and is not checked."""
    out: dict[str, dict[str, Any]] = {}
    for split, rows in episodes.groupby("split", sort=False):
        rows = rows.reset_index(drop=True)  # concatenated results repeat index labels
        if COLUMN not in rows or rows[COLUMN].isna().any():
            out[str(split)] = {
                "recorded": False,
                "blocks": int(rows.groupby(list(BLOCK)).ngroups),
                "verified": 0,
                "violations": [],
            }
            continue
        varied = _varied(rows)
        riding = _riding(rows)
        free = allowed_to_differ(varied) | set(riding)
        parsed = rows[COLUMN].map(json.loads)
        violations = []
        blocks = 0
        for (context, repeat), index in rows.groupby(list(BLOCK), sort=True).groups.items():
            blocks += 1
            certs = parsed.loc[index]
            keys = sorted(set().union(*certs.map(set)) - free)
            differing = [k for k in keys if len({c.get(k) for c in certs}) > 1]
            if differing:
                violations.append(
                    {
                        "context_id": str(context),
                        "repeat": int(repeat),
                        "components": differing,
                        "values": sorted(map(str, rows.loc[index, "value"])),
                    }
                )
        out[str(split)] = {
            "recorded": True,
            "blocks": blocks,
            "verified": blocks - len(violations),
            "violations": violations,
            "varied": list(varied),
            "allowed_to_differ": sorted(free),
            "changes": [*varied, *riding],
            "cameras": cameras_changed(free),
            "isolated": len(varied) + len(riding) == 1,
        }
    return out


def _riding(rows: pd.DataFrame) -> list[str]:
    """Components that change with the values because a context factor of these rows is set away from its baseline
    and declares them (`Factor.alters` of a context factor), in factor order."""
    from roboview.variation.factors import FACTORS, baseline_of

    out: list[str] = []
    for factor in FACTORS.values():
        if factor.kind != "context" or not factor.alters or factor.name not in rows:
            continue
        if (rows[factor.name].astype(str) != baseline_of(factor.name, factor.task)).any():
            out += [c for c in factor.alters if c not in out]
    return out


def cameras_changed(components: set[str]) -> list[str]:
    """The cameras whose pose (`camera:<name>`) or frames (`image:<name>`) are among `components`, sorted."""
    return sorted({c.partition(":")[2] for c in components if c.startswith(("camera:", "image:"))})


def label(cert: dict[str, Any]) -> str:
    """What a split's values change, in words, with the cameras they change: "isolated (view_azimuth) on agentview",
    "2 changes: noise_fog + noise_wrist on agentview + wrist"."""
    changes = cert.get("changes") or []
    if not changes:
        return "not recorded"
    cameras = cert.get("cameras") or []
    on = f" on {' + '.join(cameras)}" if cameras else ""
    if cert.get("isolated"):
        return f"isolated ({changes[0]}){on}"
    return f"{len(changes)} changes: {' + '.join(changes)}{on}"


def _varied(rows: pd.DataFrame) -> tuple[str, ...]:
    """The factors a split varies: its `factor` column ("|"-joined for a factorial split), else its name."""
    if "factor" in rows:
        return tuple(str(rows["factor"].iloc[0]).split("|"))
    return tuple(str(rows["split"].iloc[0]).split("_x_"))


def drop_violations(episodes: pd.DataFrame, report: dict[str, dict[str, Any]]) -> pd.DataFrame:
    """`episodes` without the blocks that failed the certificate (each split's tests then see only
    blocks in which only the factor changed); warns once per split that lost blocks."""
    keep = np.ones(len(episodes), bool)
    for split, result in report.items():
        if not result["violations"]:
            continue
        bad = {(v["context_id"], v["repeat"]) for v in result["violations"]}
        in_split = (episodes["split"] == split).to_numpy()
        block = list(zip(episodes["context_id"].astype(str), episodes["repeat"].astype(int)))
        drop = in_split & np.array([b in bad for b in block])
        keep &= ~drop
        log.warning(
            "split %s: %d of %d blocks failed the isolation certificate (%s differ across values); "
            "their %d episodes are left out of the statistics",
            split,
            len(bad),
            result["blocks"],
            ", ".join(sorted({c for v in result["violations"] for c in v["components"]})),
            int(drop.sum()),
        )
    return episodes[keep]
