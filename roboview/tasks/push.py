"""The second task, `push`: slide the small object into a target zone marked on the table (``RoboView/Push-v0``).

Same world, robot, cameras, observations and actions as pick_place (so every visual factor applies
unchanged); its target is a flat marked square on the table — the zone — placed relative to the
object's start, so every context pushes the object about 15 cm across open table (sideways toward
the robot's right, away from the robot, or diagonally).
Its scripted expert pushes with the closed gripper: it comes down behind the object on the line to the zone
center, slides it there, backs off and lifts.

**Randomizations.** Per episode, from the episode seed: the object's start jittered around its named start
(`POSITION_JITTER_M`) and its heading (`YAW_JITTER_RAD`); the zone sits at its offset from the named start. Every value of
one (context, repeat) draws the same. The context factors (start, zone, shape, instruction) are fixed per context.

**Success.** The object's center lies inside the zone and it is at rest (slower than 5 cm/s), untouched by the
robot (`PushEnv.is_success`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.sim.motion import MotionPlanner, Segment
from roboview.tasks.base import Task, register_task
from roboview.tasks.env import POSITION_JITTER_M, REST_SPEED, YAW_JITTER_RAD, TaskEnv
from roboview.variation.factors import Factor, register_factor

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

PUSH_START = register_factor(
    Factor(
        name="push_start",
        kind="context",
        task=TASK,
        values=tuple(PUSH_STARTS),
        baseline="center",
        doc="Named start xy of the object (PUSH_STARTS).",
        title="Start position",
    )
)
ZONE = register_factor(
    Factor(
        name="zone",
        kind="context",
        task=TASK,
        values=tuple(ZONE_OFFSETS),
        baseline="right",
        doc="Where the marked target zone lies relative to the start (ZONE_OFFSETS).",
        title="Zone placement",
    )
)
PUSH_SHAPE = register_factor(
    Factor(
        name="push_shape",
        kind="context",
        task=TASK,
        values=("cube", "cuboid", "hex_prism"),
        baseline="cube",
        doc="Solid pushed (flat-sided: each slides rather than rolls).",
        title="Shape",
    )
)
PUSH_INSTRUCTION = register_factor(
    Factor(
        name="push_instruction",
        kind="context",
        task=TASK,
        values=(
            "push the small object into the marked zone",
            "slide the small object onto the marked square",
            "push the small object until it rests inside the marked area",
        ),
        baseline="push the small object into the marked zone",
        doc="Language goal: paraphrases naming neither color nor shape.",
        title="Instruction",
    )
)

# The zone: a flat marked square on the table (visual only, no collision).
ZONE_HALF = 0.05
ZONE_RGBA = (0.30, 0.55, 0.95, 1.0)

# Pinch-point height while pushing (m above the table) and standoff behind the object's face (m).
PUSH_Z = 0.016
STANDOFF_M = 0.035
APPROACH_Z = 0.10
# Where the pusher stops: this far short of putting the object's face on the zone center.
FOLLOW_THROUGH_M = 0.012


class PushEnv(TaskEnv):
    """Slide the object into the marked zone: its center inside the zone, at rest, untouched by the robot."""

    task = TASK
    instruction_factor = "push_instruction"
    target = "zone"

    @staticmethod
    def add_target(spec: mujoco.MjSpec) -> None:
        spec.worldbody.add_geom(
            name="zone",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[ZONE_HALF, ZONE_HALF, 0.0005],
            pos=[0.0, 0.0, 0.0005],
            rgba=list(ZONE_RGBA),
            contype=0,
            conaffinity=0,
        )

    def bind_target(self) -> None:
        self._zone = self.model.geom("zone").id
        self.zone_center = np.zeros(2)

    def target_geoms(self) -> tuple[int, ...]:
        return (self._zone,)

    def target_xy(self) -> np.ndarray:
        return self.zone_center.copy()

    def place_context(self, values: dict[str, str], rng: np.random.Generator) -> None:
        start = np.asarray(PUSH_STARTS[values["push_start"]])
        xy = start + rng.uniform(-POSITION_JITTER_M, POSITION_JITTER_M, size=2)
        yaw = rng.uniform(-YAW_JITTER_RAD, YAW_JITTER_RAD)
        self.scene.place_object(values["push_shape"], xy, yaw)
        self.zone_center = start + np.asarray(ZONE_OFFSETS[values["zone"]])
        self.model.geom_pos[self._zone][:2] = self.zone_center

    def is_success(self) -> bool:
        pos, _ = self.object_pose()
        if not np.all(np.abs(pos[:2] - self.zone_center) < ZONE_HALF):
            return False
        return self.object_speed() < REST_SPEED and not self.object_touches_robot()

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
        """Push along the line from the object to the zone center (`push_segments`)."""
        start = planner.pinch_position(arm_qpos) if ee_pos is None else ee_pos
        planner.follow(push_segments(planner, obj_pos[:2], target_xy, reach), start, arm_qpos)


def push_segments(
    planner: MotionPlanner, obj_xy: np.ndarray, zone_xy: np.ndarray, reach: float
) -> list[Segment]:
    """Come down behind the object on the line to the zone center, slide it there, back off, lift.

    `reach` is the object's extent along the push (m). The closed fingers' broad face meets the
    object: their closing axis is turned across the push direction.
    """
    u = (zone_xy - obj_xy) / np.linalg.norm(zone_xy - obj_xy)
    behind = obj_xy - u * (reach / 2 + STANDOFF_M)
    stop = zone_xy - u * (reach / 2 + FOLLOW_THROUGH_M)
    back = stop - u * 0.05
    yaw = planner.finger_yaw(float(np.arctan2(u[1], u[0])) + np.pi / 2)
    return [
        Segment(np.array([*behind, APPROACH_Z]), yaw, 12, 1.0),
        Segment(np.array([*behind, PUSH_Z]), yaw, 8, 1.0),
        Segment(np.array([*stop, PUSH_Z]), yaw, 28, 1.0),
        Segment(np.array([*back, PUSH_Z]), yaw, 6, 1.0),
        Segment(np.array([*back, APPROACH_Z]), yaw, 30, 1.0),
    ]


register_task(
    Task(
        name=TASK,
        gym_id="RoboView/Push-v0",
        env="roboview.tasks.push:PushEnv",
        success="the object's center lies inside the marked zone, it moves slower than 5 cm/s and touches no part of the robot",
        timeout_reason="object not at rest inside the zone",
        small_contexts=(
            ("push_start", ("center", "left")),
            ("zone", ("right", "far")),
            ("push_shape", ("cube",)),
            ("push_instruction", (PUSH_INSTRUCTION.baseline,)),
        ),
    )
)
