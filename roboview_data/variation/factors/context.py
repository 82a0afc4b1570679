"""The `pick_place` task's context factors D: where the object starts, which solid it is, the words.

They diversify the task's scenarios (the paper's Structured Union of contexts); no bias is measured
over them. The task's env places them itself (`PickPlaceEnv.reset`).
"""

from __future__ import annotations

from roboview_data.variation.factors.base import Factor, register_factor

TASK = "pick_place"

# World xy (m) of the object's initial position for each `initial_position` value. The scene
# reads them from here so that tuning a position touches exactly one table.
OBJECT_POSITIONS: dict[str, tuple[float, float]] = {
    "center": (0.50, 0.12),
    "left": (0.45, 0.26),
    "right": (0.60, 0.04),
    "near": (0.38, 0.10),
}

INITIAL_POSITION = register_factor(Factor(
    name="initial_position", kind="context", task=TASK, always_in_id=True,
    values=tuple(OBJECT_POSITIONS), baseline="center",
    doc="Named initial xy of the object on the table (OBJECT_POSITIONS).", title="Initial position",
))
SHAPE = register_factor(Factor(
    name="shape", kind="context", task=TASK, always_in_id=True,
    values=("cube", "cylinder", "hex_prism", "cuboid"), baseline="cube",
    doc="Solid of the manipulated object, each graspable by the 2F-85 gripper.", title="Shape",
))
INSTRUCTION = register_factor(Factor(
    name="instruction", kind="context", task=TASK, always_in_id=True,
    values=(
        "put the small object into the yellow box",
        "pick up the small object and place it in the yellow box",
        "move the small object into the yellow box",
    ),
    baseline="put the small object into the yellow box",
    doc="Language goal: paraphrases of one task naming neither color nor shape.", title="Instruction",
))
