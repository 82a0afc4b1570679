"""LIBERO-plus's five camera sub-factors: `view_azimuth`, `view_elevation`, `view_scale`, `view_rotz`, `view_roty`.

LIBERO-plus names each camera variant by five numbers (`view_<az>_<el>_<scale %>_<rotz>_<roty>`) and moves LIBERO's
`agentview` with them in five rounded steps (roboview.libero.plus). Declared as five factors, an instance says
which of them it changes, so a variant that changes two (azimuth with elevation, rotation z with rotation y) is a
two-factor instance, never an isolated one, and each part can be run alone.

The grids are LIBERO-plus's ranges, as its names write them (angles in degrees 0–359, −d written 360 − d):
azimuth within ±75° by 1°, elevation +15°, scale 101–200 % by 1 %, rotations z and y within ±10° by 2°. They apply
to LIBERO's scenes (the `liberoplus` task, and the `libero` task), whose world's applier table takes them
(roboview.libero.task: LIBERO-plus's pose arithmetic, roboview.libero.plus). They bring no applier for RoboView's own
scene, which has no agentview: that scene, as Meta-World's, lacks them and refuses a value away from the baseline.
"""

from __future__ import annotations

from roboview.variation.factors import Factor, register_factor

MOVED = ("camera:agentview",)


def signed(limit: int, step: int) -> tuple[str, ...]:
    """Nonzero angles within ±limit by `step`, written as LIBERO-plus writes them (0–359)."""
    return tuple(str(d) for d in range(step, limit + 1, step)) + tuple(
        str(360 - d) for d in range(limit - limit % step, 0, -step)
    )


def view_factor(name: str, values: tuple[str, ...], baseline: str, doc: str, title: str) -> Factor:
    return register_factor(
        Factor(name=name, kind="visual", values=values, baseline=baseline, doc=doc, title=title, alters=MOVED)
    )


VIEW_AZIMUTH = view_factor(
    "view_azimuth",
    signed(75, 1),
    "0",
    "LIBERO-plus's azimuth (degrees, 0–359): agentview rotated about the world vertical through the origin.",
    "View azimuth",
)
VIEW_ELEVATION = view_factor(
    "view_elevation",
    ("15",),
    "0",
    "LIBERO-plus's elevation (degrees): agentview orbited up about the line through (0, 0, 0.8) parallel to y.",
    "View elevation",
)
VIEW_SCALE = view_factor(
    "view_scale",
    tuple(str(s) for s in range(101, 201)),
    "100",
    "LIBERO-plus's scale (percent): agentview moved along the ray from (0, 0, 0.8), its distance × scale / 100.",
    "View scale",
)
VIEW_ROTZ = view_factor(
    "view_rotz",
    signed(10, 2),
    "0",
    "LIBERO-plus's rotation z (degrees, 0–359): agentview panned about the world vertical, in place.",
    "View rotation z",
)
VIEW_ROTY = view_factor(
    "view_roty",
    signed(10, 2),
    "0",
    "LIBERO-plus's rotation y (degrees, 0–359): agentview tilted about the world y axis, in place.",
    "View rotation y",
)
