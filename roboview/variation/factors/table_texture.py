"""`table_texture`: procedural MuJoCo textures on the table (no image files); `plain` is today's table.

Each non-plain value is a builtin 2D texture (checker, gradient, or flat with marks) in a colourway
near the plain table's, compiled into the scene once (`extend_spec`) as a material; the applier
switches the table geom's material in place (`geom_matid`), -1 for plain.
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.variation.factors.base import Factor, register_factor

BASELINE = "plain"
# value: (builtin, mark, rgb1, rgb2, markrgb, random, texrepeat)
TEXTURES = {
    "checker_light": ("checker", "none", (0.62, 0.58, 0.52), (0.50, 0.46, 0.41), (0, 0, 0), 0.0, 8),
    "checker_dark": ("checker", "none", (0.42, 0.39, 0.35), (0.30, 0.28, 0.26), (0, 0, 0), 0.0, 8),
    "gradient_sand": ("gradient", "none", (0.70, 0.63, 0.50), (0.45, 0.40, 0.32), (0, 0, 0), 0.0, 1),
    "gradient_slate": ("gradient", "none", (0.55, 0.57, 0.60), (0.33, 0.35, 0.38), (0, 0, 0), 0.0, 1),
    "grid_lines": ("flat", "edge", (0.56, 0.52, 0.47), (0.56, 0.52, 0.47), (0.25, 0.23, 0.21), 0.0, 10),
    "speckle": ("flat", "random", (0.56, 0.52, 0.47), (0.56, 0.52, 0.47), (0.32, 0.30, 0.27), 0.08, 4),
    "cross_marks": ("flat", "cross", (0.60, 0.56, 0.50), (0.60, 0.56, 0.50), (0.35, 0.33, 0.30), 0.0, 6),
}
VALUES = (BASELINE, *TEXTURES)
_BUILTIN = {
    "checker": mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
    "gradient": mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
    "flat": mujoco.mjtBuiltin.mjBUILTIN_FLAT,
}
_MARK = {
    "none": mujoco.mjtMark.mjMARK_NONE,
    "edge": mujoco.mjtMark.mjMARK_EDGE,
    "cross": mujoco.mjtMark.mjMARK_CROSS,
    "random": mujoco.mjtMark.mjMARK_RANDOM,
}


def add_textures(spec: mujoco.MjSpec) -> None:
    for name, (builtin, mark, rgb1, rgb2, markrgb, random, repeat) in TEXTURES.items():
        spec.add_texture(
            name=f"table_{name}",
            type=mujoco.mjtTexture.mjTEXTURE_2D,
            builtin=_BUILTIN[builtin],
            mark=_MARK[mark],
            rgb1=list(rgb1),
            rgb2=list(rgb2),
            markrgb=list(markrgb),
            random=random,
            width=256,
            height=256,
        )
        material = spec.add_material(name=f"table_{name}", texrepeat=[repeat, repeat], texuniform=True)
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"table_{name}"


class TableMaterial:
    def __init__(self, scene) -> None:
        self.geom_matid, self.geom_rgba = scene.model.geom_matid, scene.model.geom_rgba
        self.table = scene.ids.table_geom
        self.plain_rgba = self.geom_rgba[self.table].copy()
        self.materials = {name: scene.model.material(f"table_{name}").id for name in TEXTURES}

    def apply(self, value: str, rng: np.random.Generator) -> None:
        TABLE_TEXTURE.validate(value)
        plain = value == BASELINE
        self.geom_matid[self.table] = -1 if plain else self.materials[value]
        # The geom's rgba tints its material: white lets the texture's own colours through.
        self.geom_rgba[self.table] = self.plain_rgba if plain else (1.0, 1.0, 1.0, 1.0)


TABLE_TEXTURE = register_factor(
    Factor(
        name="table_texture",
        kind="visual",
        values=VALUES,
        baseline=BASELINE,
        title="Table texture",
        doc="Procedural texture on the table: checker, gradient or marked flat colourways near the plain table's.",
        bind=TableMaterial,
        extend_spec=add_textures,
    )
)
