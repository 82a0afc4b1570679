"""The `push` task's context factors: where the object starts, where the zone is, which solid, the words.

Zones are placed relative to the start, so every context pushes the object about 15 cm across open
table (the receiver box is parked for this task): sideways toward the robot's right, away from the
robot, or diagonally.
"""

from __future__ import annotations

from roboview_data.variation.factors.base import Factor, register_factor

TASK = "push"

# World xy (m) of the object's start, and the zone center's offset from it.
PUSH_STARTS: dict[str, tuple[float, float]] = {
    "center": (0.48, 0.12),
    "left": (0.44, 0.22),
    "near": (0.40, 0.08),
}
ZONE_OFFSETS: dict[str, tuple[float, float]] = {
    "right": (0.0, -0.15),
    "far": (0.14, 0.0),
    "diagonal": (0.10, -0.11),
}

PUSH_START = register_factor(Factor(
    name="push_start", kind="context", task=TASK, values=tuple(PUSH_STARTS), baseline="center",
    doc="Named start xy of the object (PUSH_STARTS).", title="Start position",
))
ZONE = register_factor(Factor(
    name="zone", kind="context", task=TASK, values=tuple(ZONE_OFFSETS), baseline="right",
    doc="Where the marked target zone lies relative to the start (ZONE_OFFSETS).", title="Zone placement",
))
PUSH_SHAPE = register_factor(Factor(
    name="push_shape", kind="context", task=TASK, values=("cube", "cuboid", "hex_prism"), baseline="cube",
    doc="Solid pushed (flat-sided: each slides rather than rolls).", title="Shape",
))
PUSH_INSTRUCTION = register_factor(Factor(
    name="push_instruction", kind="context", task=TASK,
    values=("push the small object into the marked zone", "slide the small object onto the marked square",
            "push the small object until it rests inside the marked area"),
    baseline="push the small object into the marked zone",
    doc="Language goal: paraphrases naming neither color nor shape.", title="Instruction",
))
