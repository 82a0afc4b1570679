"""`color`: the manipulated object's RGB, one of 141 CSS named colors (roboview.variation.colors).

The registered baseline is `red`, the color of RoboView's own object. A world whose object keeps its own look at
the baseline (LIBERO's and Meta-World's textures) labels that baseline `original` (`World.baseline_labels`): there
every CSS color, red included, is a re-skin, and `original` records no nominal color."""

from __future__ import annotations

import numpy as np

from roboview.variation.colors import COLORS, get_color
from roboview.variation.factors.base import Factor, register_factor


class ObjectColor:
    """Writes the color into the rgba of the object the task placed (`scene.active_geom`)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self.geom_rgba = scene.model.geom_rgba  # a view: writes go straight into the compiled model

    def apply(self, value: str, rng: np.random.Generator) -> None:
        self.geom_rgba[self.scene.active_geom] = [*get_color(value).rgb, 1.0]


def _columns(value: str) -> dict:
    """The value's hex, sRGB and CIELAB; a world's own look (a baseline label, not a CSS color: `original`) has no
    nominal color: an empty hex and null sRGB and Lab (the columns' types stay those of a color)."""
    if value not in COLORS:
        return {"color_hex": "", "color_rgb": None, "color_lab": None}
    color = get_color(value)
    return {"color_hex": color.hex, "color_rgb": list(color.rgb), "color_lab": list(color.lab)}


COLOR = register_factor(
    Factor(
        name="color",
        kind="visual",
        values=tuple(sorted(COLORS)),
        baseline="red",
        doc="RGB of the manipulated object: a CSS named color (roboview.variation.colors).",
        title="Color",
        bind=ObjectColor,
        record_columns=_columns,
        always_in_id=True,
    )
)
