"""Coverage audit: which benchmark factor values a training dataset's frames already showed.

A policy trained on red objects seen from `left_top` has seen the `red` test value *exactly*; one
trained with color randomization has seen colors *nearby* most test colors. Either is leakage
between training and test that a bias profile must be read against. For every value of every
visual split the audit reports:

- ``exact``: some training episode showed this value (ΔE2000 ≤ 0.01; camera within 1 mm, 0.01° and
  0.01° of fovy),
- ``nearby``: some episode came within the radius (ΔE2000 ≤ `color_radius` in CIELAB; camera
  within `pose_radius_m` and `pose_angle_deg`, fovy ignored),
- ``never``: none did,

together with the distance to the nearest training episode and how many episodes lie within the
radius. Camera values are compared on the first recorded camera that the camera factors move
(`left_top` or `front`); a dataset recording neither gets ``unobserved``. Factorial values need one
episode close in color *and* camera. Training visuals come from meta/roboview/episodes.parquet
(recorded per episode since randomization exists; older context-only collections showed the
baseline color and original cameras in every episode).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from roboview.demos.dataset import read_provenance
from roboview.sim.cameras import PERTURBED_CAMERAS, quat_to_mat
from roboview.variation.colors import delta_e_2000
from roboview.variation.factors import context_factors
from roboview.variation.randomization import baseline_randomization

STATUSES = ("exact", "nearby", "never")
EXACT_DELTA_E = 0.01
EXACT_POS_M, EXACT_ANGLE_DEG, EXACT_FOVY_DEG = 1e-3, 0.01, 0.01


@dataclass(frozen=True)
class Radii:
    color_delta_e: float = 5.0
    pose_m: float = 0.05
    pose_deg: float = 5.0


@dataclass
class TrainingVisuals:
    """Per-episode visuals of a dataset: CIELAB of the object and pose of the audited camera."""

    lab: np.ndarray  # (N, 3)
    camera: str | None  # audited camera, None when the dataset records no perturbed camera
    pos: np.ndarray  # (N, 3)
    rot: np.ndarray  # (N, 3, 3)
    fovy: np.ndarray  # (N,)
    contexts: set[tuple[str, ...]]
    randomized: tuple[str, ...]

    @property
    def n(self) -> int:
        return len(self.lab)


def load_training_visuals(root: str | Path) -> TrainingVisuals:
    prov, cameras = read_provenance(root)
    audited = next((c for c in cameras if c in PERTURBED_CAMERAS), None)
    base = baseline_randomization()
    n = len(prov)
    if "object_lab" in prov:
        lab = np.stack(prov["object_lab"].map(np.asarray).to_list())
    else:  # context-only collection made before visuals were recorded: the baseline in every episode
        lab = np.tile(np.asarray(base.record()["object_lab"]), (n, 1))
    pos, rot, fovy = np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), np.zeros(n)
    if audited is not None:
        if f"camera_{audited}_pos" in prov:
            pos = np.stack(prov[f"camera_{audited}_pos"].map(np.asarray).to_list())
            rot = np.stack([quat_to_mat(np.asarray(q)) for q in prov[f"camera_{audited}_quat"]])
            fovy = prov[f"camera_{audited}_fovy"].to_numpy(float)
        else:
            pose = base.cameras[audited]
            pos, rot = np.tile(pose.pos, (n, 1)), np.tile(pose.rotation, (n, 1, 1))
            fovy = np.full(n, pose.fovy)
    randomized = tuple(prov["randomized"].iloc[0]) if "randomized" in prov and n else ()
    contexts = {tuple(str(r[f]) for f in context_factors()) for r in prov.to_dict("records")}
    return TrainingVisuals(lab, audited, pos, rot, fovy, contexts, randomized)


def _rotation_angle_deg(rot: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Geodesic angle between each rotation in `rot` (N, 3, 3) and `target` (3, 3)."""
    cos = (np.einsum("nij,ij->n", rot, target) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _status(exact: np.ndarray, near: np.ndarray) -> str:
    return "exact" if exact.any() else "nearby" if near.any() else "never"


def audit(visuals: TrainingVisuals, records: list[dict], radii: Radii = Radii()) -> pd.DataFrame:
    """One row per (split, value): status, nearest distances and episodes within the radius.

    `records` are benchmark instance rows (split, factor, value, color_lab, cameras, context factors).
    """
    rows = []
    seen: set[tuple[str, str]] = set()
    contexts: dict[tuple[str, str], list[bool]] = {}
    for rec in records:
        key = (rec["split"], rec["value"])
        contexts.setdefault(key, []).append(tuple(str(rec[f]) for f in context_factors()) in visuals.contexts)
        if key in seen:
            continue
        seen.add(key)
        factors = rec["factor"].split("|")
        row = {"split": rec["split"], "value": rec["value"]}
        color_ok = camera_ok = (np.ones(visuals.n, bool), np.ones(visuals.n, bool))
        if "color" in factors:
            de = delta_e_2000(visuals.lab, np.asarray(rec["color_lab"], float)[None, :])
            row["nearest_delta_e"] = float(de.min()) if len(de) else float("nan")
            color_ok = (de <= EXACT_DELTA_E, de <= radii.color_delta_e)
        camera_factors = [f for f in factors if f != "color"]
        if camera_factors and visuals.camera is None:
            row["status"] = "unobserved"
            rows.append(row)
            continue
        if camera_factors:
            pose = next(c for c in rec["cameras"] if c["name"] == visuals.camera)
            dist = np.linalg.norm(visuals.pos - np.asarray(pose["pos"]), axis=1)
            angle = _rotation_angle_deg(visuals.rot, quat_to_mat(np.asarray(pose["quat"], float)))
            dfovy = np.abs(visuals.fovy - pose["fovy"])
            best = int(np.argmin(dist / radii.pose_m + angle / radii.pose_deg)) if len(dist) else None
            row["nearest_pos_m"] = float(dist[best]) if best is not None else float("nan")
            row["nearest_angle_deg"] = float(angle[best]) if best is not None else float("nan")
            camera_ok = (
                (dist <= EXACT_POS_M) & (angle <= EXACT_ANGLE_DEG) & (dfovy <= EXACT_FOVY_DEG),
                (dist <= radii.pose_m) & (angle <= radii.pose_deg),
            )
        exact, near = color_ok[0] & camera_ok[0], color_ok[1] & camera_ok[1]
        row["status"] = _status(exact, near)
        row["n_nearby"] = int(near.sum())
        rows.append(row)
    table = pd.DataFrame(rows)
    table["contexts_in_training"] = [
        float(np.mean(contexts[(s, v)])) for s, v in zip(table["split"], table["value"])
    ]
    return table


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Counts of values per status, per split."""
    counts = table.groupby(["split", "status"]).size().unstack(fill_value=0)
    for status in (*STATUSES, "unobserved"):
        if status not in counts:
            counts[status] = 0
    counts = counts[[*STATUSES, "unobserved"]]
    return counts.loc[[s for s in dict.fromkeys(table["split"])]]
