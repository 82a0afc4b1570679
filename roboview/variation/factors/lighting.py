"""`lighting`: the key light at 3 intensities × 3 directions; `default` is the scene's own light.

The key light is the scene's `top` light (roboview.sim.scene). Intensity scales its diffuse
colour (dim 0.45×, normal 1×, bright 1.6× of the scene's 0.45); direction moves it (and aims it at the
workspace center): straight above, from the robot's left (+y), or from the front (+x, behind the
`front` camera). The headlight (ambient 0.35) stays, so nothing ever goes black.
"""

from __future__ import annotations

import numpy as np

from roboview.sim.cameras import WORKSPACE_CENTER
from roboview.variation.factors.base import Factor, register_factor

KEY_LIGHT = "top"
BASE_DIFFUSE = 0.45
INTENSITIES = {"dim": 0.45, "normal": 1.0, "bright": 1.6}
POSITIONS = {"top": (0.4, 0.0, 2.0), "left": (0.45, 1.4, 1.1), "front": (1.6, 0.0, 1.1)}
BASELINE = "default"  # = normal intensity from the top: the scene as built


def _name(intensity: str, direction: str) -> str:
    return BASELINE if (intensity, direction) == ("normal", "top") else f"{intensity}_{direction}"


VALUES = tuple(_name(i, d) for d in POSITIONS for i in INTENSITIES)


def parse_lighting(value: str) -> tuple[float, np.ndarray, np.ndarray]:
    """(diffuse level, position, unit direction) of the key light for a value."""
    LIGHTING.validate(value)
    intensity, direction = ("normal", "top") if value == BASELINE else value.split("_")
    pos = np.asarray(POSITIONS[direction], dtype=float)
    aim = (
        np.array([0.0, 0.0, -1.0])
        if direction == "top"
        else (WORKSPACE_CENTER - pos) / np.linalg.norm(WORKSPACE_CENTER - pos)
    )
    return BASE_DIFFUSE * INTENSITIES[intensity], pos, aim


class KeyLight:
    def __init__(self, scene) -> None:
        self.model = scene.model
        self.light = scene.model.light(KEY_LIGHT).id

    def apply(self, value: str, rng: np.random.Generator) -> None:
        level, pos, aim = parse_lighting(value)
        self.model.light_diffuse[self.light] = level
        self.model.light_pos[self.light] = pos
        self.model.light_dir[self.light] = aim


LIGHTING = register_factor(
    Factor(
        name="lighting",
        kind="visual",
        values=VALUES,
        baseline=BASELINE,
        title="Lighting",
        doc="Key light: intensity (dim, normal, bright) × direction (top, left, front); default = normal from the top.",
        bind=KeyLight,
        keeps_nominal_color=False,
    )
)
