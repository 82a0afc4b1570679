"""`distractors`: 0–4 larger objects of other colours and shapes on the table.

Four static bodies (a block, a cylinder, a ball, a tall box: each clearly larger than the small
object, so "the small object" of every instruction stays unique) are compiled into the scene once,
parked off the table; value n places the first n on fixed slots chosen so that none overlaps any
initial position of the object (with its jitter), the box, or the path the object is carried along,
and none stands between the observed cameras and the object or the box at baseline (checked by the
fairness gate and by `tests/variation/test_extended_factors.py` over every context and seed of the suite).
Their colours come from a fixed palette, skipping any within ΔE2000 25 of the object's colour.
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.variation.colors import delta_e_2000, srgb_to_lab
from roboview.variation.factors.base import Factor, register_factor

PARK = np.array([-3.0, 1.5])
# (name, geom type, size, half height): each larger than the 4 cm object.
BODIES = (
    ("block", mujoco.mjtGeom.mjGEOM_BOX, (0.035, 0.03, 0.03), 0.03),
    ("drum", mujoco.mjtGeom.mjGEOM_CYLINDER, (0.035, 0.035, 0.0), 0.035),
    ("ball", mujoco.mjtGeom.mjGEOM_SPHERE, (0.035, 0.0, 0.0), 0.035),
    ("tower", mujoco.mjtGeom.mjGEOM_BOX, (0.025, 0.025, 0.05), 0.05),
)
# World xy (m) of the slots, in the order distractors are added.
SLOTS = ((0.66, 0.30), (0.68, -0.22), (0.30, 0.36), (0.28, -0.32))
PALETTE = (
    (0.15, 0.35, 0.85),
    (0.10, 0.60, 0.25),
    (0.55, 0.20, 0.65),
    (0.90, 0.45, 0.10),
    (0.85, 0.15, 0.20),
    (0.10, 0.55, 0.60),
)
MIN_DELTA_E = 25.0
VALUES = tuple(str(n) for n in range(len(BODIES) + 1))


def add_bodies(spec: mujoco.MjSpec) -> None:
    for i, (name, geom_type, size, half_height) in enumerate(BODIES):
        body = spec.worldbody.add_body(
            name=f"distractor_{name}", pos=[PARK[0], PARK[1] + 0.2 * i, half_height]
        )
        body.add_geom(name=f"distractor_{name}", type=geom_type, size=list(size), rgba=[0.5, 0.5, 0.5, 1.0])


def palette_for(object_rgb: np.ndarray) -> list[tuple[float, float, float]]:
    """Palette colours far enough from the object's colour, in palette order."""
    lab = srgb_to_lab(np.asarray(object_rgb, dtype=float))
    return [c for c in PALETTE if float(delta_e_2000(srgb_to_lab(np.asarray(c)), lab)) >= MIN_DELTA_E]


class Distractors:
    def __init__(self, scene) -> None:
        self.scene = scene
        model = scene.model
        self.bodies = [model.body(f"distractor_{name}").id for name, *_ in BODIES]
        self.geoms = [model.geom(f"distractor_{name}").id for name, *_ in BODIES]

    def apply(self, value: str, rng: np.random.Generator) -> None:
        n = int(DISTRACTORS.validate(value))
        model = self.scene.model
        colors = palette_for(model.geom_rgba[self.scene.active_geom][:3])
        for i, (body, geom, (_, _, _, half_height)) in enumerate(zip(self.bodies, self.geoms, BODIES)):
            xy = SLOTS[i] if i < n else (PARK[0], PARK[1] + 0.2 * i)
            model.body_pos[body] = [xy[0], xy[1], half_height]
            model.geom_rgba[geom] = [*colors[i % len(colors)], 1.0] if i < n else [0.5, 0.5, 0.5, 1.0]


DISTRACTORS = register_factor(
    Factor(
        name="distractors",
        kind="visual",
        values=VALUES,
        baseline="0",
        title="Distractors",
        doc="Number of larger objects of other colours and shapes placed on fixed, non-occluding slots.",
        bind=Distractors,
        extend_spec=add_bodies,
    )
)
