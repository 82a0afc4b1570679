"""The paper's task, `pick_place`: put the small object into the open yellow box (``RoboView/PickPlace-v0``).

Everything of the task in one module: its context factors D (where the object starts, which solid
it is, the words: they diversify its scenarios, no bias is measured over them), its receiver box
(the target), how a context places the scene, its success test, its scripted solution (grasp,
carry, release above the box) and its registry line.

**Randomizations.** Per episode, from the episode seed: the object's start ± 1 cm in x and y around its named
position and its heading ± 0.35 rad (`POSITION_JITTER_M`, `YAW_JITTER_RAD`); every value of one (context,
repeat) draws the same. The context factors (`initial_position`, `shape`, `instruction`) are fixed per context.

**Success.** The object's center lies inside the box's inner walls, below the rim (+1 cm), it moves slower than
the rest speed, the gripper has released it and no part of the robot touches it (`PickPlaceEnv.is_success`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.sim.motion import MotionPlanner
from roboview.tasks.base import Task, register_task
from roboview.tasks.env import POSITION_JITTER_M, RELEASED_GRIPPER, REST_SPEED, YAW_JITTER_RAD, TaskEnv
from roboview.variation.factors import DEFAULT_TASK, Factor, register_factor

TASK = DEFAULT_TASK

# World xy (m) of the object's initial position for each `initial_position` value.
OBJECT_POSITIONS: dict[str, tuple[float, float]] = {
    "center": (0.50, 0.12),
    "left": (0.45, 0.26),
    "right": (0.60, 0.04),
    "near": (0.38, 0.10),
}

INITIAL_POSITION = register_factor(
    Factor(
        name="initial_position",
        kind="context",
        task=TASK,
        always_in_id=True,
        values=tuple(OBJECT_POSITIONS),
        baseline="center",
        doc="Named initial xy of the object on the table (OBJECT_POSITIONS).",
        title="Initial position",
    )
)
SHAPE = register_factor(
    Factor(
        name="shape",
        kind="context",
        task=TASK,
        always_in_id=True,
        values=("cube", "cylinder", "hex_prism", "cuboid"),
        baseline="cube",
        doc="Solid of the manipulated object, each graspable by the 2F-85 gripper.",
        title="Shape",
    )
)
INSTRUCTION = register_factor(
    Factor(
        name="instruction",
        kind="context",
        task=TASK,
        always_in_id=True,
        values=(
            "put the small object into the yellow box",
            "pick up the small object and place it in the yellow box",
            "move the small object into the yellow box",
        ),
        baseline="put the small object into the yellow box",
        doc="Language goal: paraphrases of one task naming neither color nor shape.",
        title="Instruction",
    )
)

# Receiver: open-top hollow box. Center on the table (m), inner half-width, wall height/thickness.
BOX_RGBA = (0.98, 0.82, 0.10, 1.0)
BOX_CENTER = np.array([0.45, -0.22])
BOX_INNER_HALF = 0.075
BOX_WALL_HEIGHT = 0.06
BOX_WALL_THICK = 0.008
BOX_FLOOR_THICK = 0.008
# The pinch point's height when the gripper opens above the box.
RELEASE_Z = BOX_WALL_HEIGHT + 0.08


class PickPlaceEnv(TaskEnv):
    """Franka Panda + Robotiq 2F-85 puts one small object into an open yellow box.

    **Success conditions** — the object's center lies inside the box's inner walls and below the
    rim, it moves slower than 5 cm/s, it touches no part of the robot, and the gripper is open
    (released). The episode terminates on success and truncates after `max_steps`.
    """

    task = TASK
    instruction_factor = "instruction"
    target = "box"

    @staticmethod
    def add_target(spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name="box", pos=[BOX_CENTER[0], BOX_CENTER[1], 0.0])
        half_out = BOX_INNER_HALF + BOX_WALL_THICK
        body.add_geom(
            name="box_floor",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            rgba=BOX_RGBA,
            size=[half_out, half_out, BOX_FLOOR_THICK / 2],
            pos=[0, 0, BOX_FLOOR_THICK / 2],
        )
        wall_z = BOX_WALL_HEIGHT / 2
        half_t = BOX_WALL_THICK / 2
        walls = {
            "box_wall_px": ([BOX_INNER_HALF + half_t, 0, wall_z], [half_t, half_out, wall_z]),
            "box_wall_nx": ([-BOX_INNER_HALF - half_t, 0, wall_z], [half_t, half_out, wall_z]),
            "box_wall_py": ([0, BOX_INNER_HALF + half_t, wall_z], [BOX_INNER_HALF, half_t, wall_z]),
            "box_wall_ny": ([0, -BOX_INNER_HALF - half_t, wall_z], [BOX_INNER_HALF, half_t, wall_z]),
        }
        for name, (pos, size) in walls.items():
            body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=pos, size=size, rgba=BOX_RGBA)

    def bind_target(self) -> None:
        box = self.model.body("box").id
        self._box_geoms = tuple(i for i in range(self.model.ngeom) if self.model.geom_bodyid[i] == box)

    def target_geoms(self) -> tuple[int, ...]:
        return self._box_geoms

    def target_xy(self) -> np.ndarray:
        return BOX_CENTER.copy()

    def place_context(self, values: dict[str, str], rng: np.random.Generator) -> None:
        """The object at its named position (± 1 cm, ± 0.35 rad); the box stays where it is."""
        xy = np.asarray(OBJECT_POSITIONS[values["initial_position"]])
        xy = xy + rng.uniform(-POSITION_JITTER_M, POSITION_JITTER_M, size=2)
        yaw = rng.uniform(-YAW_JITTER_RAD, YAW_JITTER_RAD)
        self.scene.place_object(values["shape"], xy, yaw)

    def is_success(self) -> bool:
        pos, _ = self.object_pose()
        rel = pos[:2] - BOX_CENTER
        inside = bool(np.all(np.abs(rel) < BOX_INNER_HALF) and pos[2] < BOX_WALL_HEIGHT + 0.01)
        if not inside:
            return False
        released = self.gripper_closure() < RELEASED_GRIPPER
        return self.object_speed() < REST_SPEED and released and not self.object_touches_robot()

    @staticmethod
    def plan(
        planner: MotionPlanner,
        obj_pos: np.ndarray,
        obj_yaw: float,
        symmetry: float,
        reach: float,
        target_xy: np.ndarray | None,
        arm_qpos: np.ndarray,
        ee_pos: np.ndarray | None = None,
    ) -> None:
        """Grasp, carry over the box, lower, open, retreat (`MotionPlanner.plan`)."""
        planner.plan(
            obj_pos, obj_yaw, symmetry, arm_qpos, box_xy=target_xy, release_z=RELEASE_Z, ee_pos=ee_pos
        )


register_task(
    Task(
        name=TASK,
        gym_id="RoboView/PickPlace-v0",
        env="roboview.tasks.pick_place:PickPlaceEnv",
        success=(
            "the object's center lies inside the box below its rim, moves slower than 5 cm/s, touches no "
            "part of the robot, and the gripper is open"
        ),
        timeout_reason="object not released inside the box",
        small_contexts=(
            ("initial_position", ("center", "left")),
            ("shape", ("cube", "cylinder")),
            ("instruction", (INSTRUCTION.baseline,)),
        ),
    )
)
