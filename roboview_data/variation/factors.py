"""Declarative registry of the benchmark's variable factors: values and baselines in one place.

The paper (§5.1) partitions factors into visual perturbation dimensions V, whose bias we measure,
and task context dimensions D, which only diversify the scenarios. Every factor value is a string
exactly as it is stored in the instance records, so the records, the samplers and the env all
speak one vocabulary; the small parsers below turn the camera strings into numbers.

    >>> load_factor("dist_scale").values
    ('0', '1', '2', '3', '4', '5', '6', '7', '8')
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

from roboview_data.variation.colors import COLORS

FACTOR_KINDS = ("visual", "context")


@dataclass(frozen=True)
class Factor:
    """One variable factor: the values a split sweeps, its baseline and what it means.

    `values` are the swept values. The baseline is usually one of them; for `camera_pose` it is
    not (the unperturbed cameras are not an orbital pose), so use `is_valid` / `validate`, which
    accept the baseline too, to check a stored value.
    """

    # Factor name as used in records and split names.
    name: str
    # "visual" (V: bias is measured over it) or "context" (D: diversifies task scenarios).
    kind: str
    # The values a split over this factor sweeps, in their canonical order.
    values: tuple[str, ...]
    # The value held fixed while other factors vary (paper's b_k or g_k).
    baseline: str
    # What a value means physically.
    doc: str

    def __post_init__(self) -> None:
        if self.kind not in FACTOR_KINDS:
            raise ValueError(f"factor {self.name!r}: kind {self.kind!r} not in {FACTOR_KINDS}")
        if not self.values:
            raise ValueError(f"factor {self.name!r} has no values")
        if len(set(self.values)) != len(self.values):
            raise ValueError(f"factor {self.name!r} has duplicate values")

    def is_valid(self, value: str) -> bool:
        """True for a swept value or the baseline."""
        return value == self.baseline or value in self.values

    def validate(self, value: str) -> str:
        """Return `value` if valid; otherwise raise naming the value and the allowed set."""
        if self.is_valid(value):
            return value
        allowed = self.values if self.baseline in self.values else (self.baseline, *self.values)
        close = difflib.get_close_matches(str(value), allowed, n=3)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        raise ValueError(f"unknown {self.name} {value!r}; allowed: {', '.join(allowed)}{hint}")


# Orbital cameras: 3 concentric rings x 7 poses, ring-major (paper appendix A).
N_ORBIT_RINGS = 3
N_ORBIT_POSES_PER_RING = 7
CAMERA_POSE_BASELINE = "original"
EULER_STEPS_DEG = (-6, 0, 6)
DIST_SCALE_STEP_M = 0.05
N_DIST_SCALE_LEVELS = 9

# World xy (m) of the object's initial position for each `initial_position` value. The scene
# reads them from here so that tuning a position touches exactly one table.
OBJECT_POSITIONS: dict[str, tuple[float, float]] = {
    "center": (0.50, 0.12),
    "left": (0.45, 0.26),
    "right": (0.60, 0.04),
    "near": (0.38, 0.10),
}

VISUAL_FACTORS = ("color", "camera_pose", "camera_euler", "dist_scale")
CONTEXT_FACTORS = ("initial_position", "shape", "instruction")
FACTOR_NAMES = VISUAL_FACTORS + CONTEXT_FACTORS

_FACTOR_LIST = (
    Factor(
        name="color",
        kind="visual",
        values=tuple(sorted(COLORS)),
        baseline="red",
        doc="RGB of the manipulated object: a CSS named color (roboview_data.variation.colors).",
    ),
    Factor(
        name="camera_pose",
        kind="visual",
        values=tuple(
            f"orbit_r{ring}_{k}"
            for ring in range(N_ORBIT_RINGS)
            for k in range(N_ORBIT_POSES_PER_RING)
        ),
        baseline=CAMERA_POSE_BASELINE,
        doc=(
            "Pose of the front and left_top cameras: one of 21 orbital poses (ring r, index k) "
            "looking at the workspace center, or 'original' for the unperturbed cameras."
        ),
    ),
    Factor(
        name="camera_euler",
        kind="visual",
        values=tuple(f"{yaw},{pitch}" for yaw in EULER_STEPS_DEG for pitch in EULER_STEPS_DEG),
        baseline="0,0",
        doc="'yaw,pitch' in degrees: rotation of front and left_top about their own axes.",
    ),
    Factor(
        name="dist_scale",
        kind="visual",
        values=tuple(str(k) for k in range(N_DIST_SCALE_LEVELS)),
        baseline="0",
        doc="k: front and left_top moved back along their optical axis by 0.05*k m.",
    ),
    Factor(
        name="initial_position",
        kind="context",
        values=tuple(OBJECT_POSITIONS),
        baseline="center",
        doc="Named initial xy of the object on the table (OBJECT_POSITIONS).",
    ),
    Factor(
        name="shape",
        kind="context",
        values=("cube", "cylinder", "hex_prism", "cuboid"),
        baseline="cube",
        doc="Solid of the manipulated object, each graspable by the 2F-85 gripper.",
    ),
    Factor(
        name="instruction",
        kind="context",
        values=(
            "put the small object into the yellow box",
            "pick up the small object and place it in the yellow box",
            "move the small object into the yellow box",
        ),
        baseline="put the small object into the yellow box",
        doc="Language goal: paraphrases of one task naming neither color nor shape.",
    ),
)

FACTORS: dict[str, Factor] = {factor.name: factor for factor in _FACTOR_LIST}
BASELINES: dict[str, str] = {factor.name: factor.baseline for factor in _FACTOR_LIST}


def load_factor(name: str) -> Factor:
    """Return the registered factor `name`; unknown names raise listing the valid ones."""
    try:
        return FACTORS[name]
    except KeyError:
        raise ValueError(
            f"unknown factor {name!r}; valid factors: {', '.join(FACTOR_NAMES)}"
        ) from None


def parse_camera_pose(value: str) -> tuple[int, int] | None:
    """Parse 'orbit_r{ring}_{k}' into (ring, k); None means the unperturbed ('original') cameras."""
    FACTORS["camera_pose"].validate(value)
    if value == CAMERA_POSE_BASELINE:
        return None
    ring, k = value.removeprefix("orbit_r").split("_")
    return int(ring), int(k)


def parse_euler(value: str) -> tuple[int, int]:
    """Parse a camera_euler value 'yaw,pitch' into integer degrees (yaw_deg, pitch_deg)."""
    FACTORS["camera_euler"].validate(value)
    yaw, pitch = value.split(",")
    return int(yaw), int(pitch)


def parse_dist_scale(value: str) -> int:
    """Parse a dist_scale value into k; the camera moves back DIST_SCALE_STEP_M * k metres."""
    FACTORS["dist_scale"].validate(value)
    return int(value)
