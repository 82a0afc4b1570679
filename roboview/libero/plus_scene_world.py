"""LIBERO-plus's light and background scenes in LIBERO's world: the `scene_light` and `scene_background` factors and
their applier, which has LIBERO's problem class build its arena from LIBERO-plus's scene file.

A value of either factor is one of LIBERO-plus's problem classes
(`Libero_Floor_Manipulation_floor_light_sync_modified_412` …), the one a variant's BDDL file names
(roboview.libero.plus_scenes); the values are those its variants name (`plus_scenes.txt`, checked against the package
by the tests). The baseline, `original`, is LIBERO's own scene.

How LIBERO-plus loads one (`liberoplus/envs/bddl_base_domain.py`, `envs/arenas/*.py`): its problem class is LIBERO's
with other constructor defaults, a `scene_xml` (relative to its asset folder) and a floor and wall style
(`scene_properties`); the base domain joins the two paths and its arena (LIBERO's arena classes, line for line) loads
that file, resolves the files it names from its own folder, and puts the style's texture file, in the same folder, in
place of the scene's `texplane` and `tex-wall` files. Its styles are those of LIBERO's style table and 267 floor and 16
wall styles more (`STYLE_MAPPING`, `envs/arenas/style.py`); where both name a style, the file is the same.

RoboView does the same with LIBERO's own classes (`LiberoPlusScene.arena`): LIBERO's problem class of the task gets
the scene file's absolute path in the asset folder and the variant's styles, and its arena builds at the world's next
reset, a hard one (roboview.libero.env: the world compiles LIBERO's model again whenever the scene changes). LIBERO's
style table is completed with LIBERO-plus's styles (`install_styles`), which leaves every style LIBERO names as it is.
Everything else (objects, fixtures, init state, cameras: agentview at LIBERO-plus's no-change pose in the `liberoplus`
task) is the task's own, as in LIBERO-plus, whose light and background variants use LIBERO's BDDL and init states.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import roboview.libero.noise  # noqa: F401  (LIBERO-plus's view_* and noise_* factors register first, whichever module is imported first)
from roboview.libero.plus_scenes import (
    DIMENSIONS,
    FACTOR,
    ORIGINAL,
    VALUES_FILE,
    assets_dir,
    check_scenes,
    scene_of,
    scene_set,
    style_files,
)
from roboview.variation.factors import Factor, register_factor


def values_of(dimension: str) -> tuple[str, ...]:
    """The problem classes LIBERO-plus's variants of `dimension` name (`VALUES_FILE`)."""
    lines = (line.split(" ", 1) for line in VALUES_FILE.read_text().splitlines() if not line.startswith("#"))
    return tuple(problem for kind, problem in lines if kind == dimension)


SCENE_LIGHT, SCENE_BACKGROUND = (
    register_factor(
        Factor(
            name=FACTOR[dimension],
            kind="visual",
            values=values_of(dimension),
            baseline=ORIGINAL,
            doc=f"LIBERO-plus's {dimension} scene: the problem class of one of its {dimension} variants, whose scene "
            f"file (from LIBERO-plus's asset folder) and floor and wall styles replace LIBERO's arena.",
            title=f"LIBERO-plus {dimension}",
            # A light scene darkens or tints every colour by design: not a fairness failure.
            keeps_nominal_color=dimension != "light",
        )
    )
    for dimension in DIMENSIONS
)


@cache
def install_styles() -> None:
    """Complete LIBERO's floor and wall style table with LIBERO-plus's (its arenas then resolve LIBERO-plus's style
    names, as LIBERO-plus's own arenas do); a LookupError where the two tables name one style's file differently."""
    from libero.libero.envs.arenas.style import STYLE_MAPPING

    for kind, theirs in style_files().items():
        ours = STYLE_MAPPING[kind]
        clash = sorted(k for k in theirs.keys() & ours.keys() if theirs[k] != ours[k])
        if clash:
            raise LookupError(f"LIBERO's and LIBERO-plus's {kind} styles {clash} name different files")
        ours.update(theirs)


@dataclass(frozen=True)
class LiberoPlusScene:
    """The LIBERO applier of `scene_light` / `scene_background`: the arena of LIBERO-plus's problem class `problem`
    (its scene file from the asset folder, its floor and wall styles), which the world loads at its next reset."""

    dimension: str
    problem: str

    @classmethod
    def of(cls, values: dict[str, str]) -> LiberoPlusScene:
        """The applier of an instance's `scene_*` values (LIBERO's `World.appliers`): one scene at a time."""
        chosen = scene_set(values)
        if chosen is None:
            raise ValueError(
                f"scene {{}}: LIBERO-plus's scene is one problem class at a time; set one of {', '.join(FACTOR.values())}"
            )
        return cls(*chosen)

    def arena(self) -> tuple[str, tuple[tuple[str, str], ...]]:
        """The scene file LIBERO's problem class builds its arena from (absolute, in the asset folder) and the arena's
        properties (`floor_style`, `wall_style`), as LIBERO-plus's problem class passes them; refused in one line
        where the folder lacks a file the scene loads."""
        scene, styles = scene_of(self.problem)
        check_scenes(self.dimension, {(scene, styles)})
        install_styles()
        return str(assets_dir() / scene), tuple((f"{kind}_style", style) for kind, style in styles)

    def apply(self, world) -> None:
        """Nothing to edit in place: the world built its model from `arena()` (which checked the folder); checked here."""
        if world.arena[0] != str(assets_dir() / scene_of(self.problem)[0]):
            raise RuntimeError(f"the world did not load the scene of {self.problem} ({world.arena[0]})")
