"""The second task, `push`: slide the small object into a target zone marked on the table.

Same scene, robot, cameras, observations and actions as pick_place (so every visual factor applies
unchanged); the receiver box is parked and a flat marked square — the zone — is placed instead.
Success: the object's center lies inside the zone and it is at rest (slower than 5 cm/s), untouched
by the robot. Its scripted expert pushes with the closed gripper: it comes down behind the object on
the line to the zone center, slides it there, backs off and lifts.
"""

from __future__ import annotations

import numpy as np

from roboview_data.sim.env import (
    POSITION_JITTER_M,
    REST_SPEED,
    YAW_JITTER_RAD,
    PickPlaceEnv,
)
from roboview_data.sim.motion import PickPlacePlanner, Segment
from roboview_data.sim.scene import SHAPES, ZONE_HALF
from roboview_data.variation.factors.push_context import PUSH_STARTS, ZONE_OFFSETS

# Pinch-point height while pushing (m above the table) and standoff behind the object's face (m).
PUSH_Z = 0.016
STANDOFF_M = 0.035
APPROACH_Z = 0.10
# Where the pusher stops: this far short of putting the object's face on the zone center.
FOLLOW_THROUGH_M = 0.012


class PushEnv(PickPlaceEnv):
    """pick_place's env with the push task's context, zone and success test (id RoboView/Push-v0)."""

    task = "push"
    instruction_factor = "push_instruction"

    def place_context(self, values: dict[str, str], rng: np.random.Generator) -> None:
        start = np.asarray(PUSH_STARTS[values["push_start"]])
        xy = start + rng.uniform(-POSITION_JITTER_M, POSITION_JITTER_M, size=2)
        yaw = rng.uniform(-YAW_JITTER_RAD, YAW_JITTER_RAD)
        self.scene.place_object(values["push_shape"], xy, yaw)
        self.zone_center = start + np.asarray(ZONE_OFFSETS[values["zone"]])
        self.scene.place_zone(self.zone_center)
        self.scene.place_box(None)

    def is_success(self) -> bool:
        pos, _ = self.object_pose()
        if not np.all(np.abs(pos[:2] - self.zone_center) < ZONE_HALF):
            return False
        dof = self.scene.ids.shape_dof[self.shape]
        speed = float(np.linalg.norm(self.data.qvel[dof:dof + 3]))
        return speed < REST_SPEED and not self.object_touches_robot()


def push_segments(planner: PickPlacePlanner, obj_xy: np.ndarray, zone_xy: np.ndarray, reach: float) -> list[Segment]:
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


class PushExpert:
    """Privileged: reads the object's pose and the zone center, then pushes along the line between them."""

    name = "expert"

    def __init__(self, env: PushEnv) -> None:
        self.env = env
        self.planner = PickPlacePlanner(env.model)

    def reset(self) -> None:
        env = self.env
        obj, _ = env.object_pose()
        reach = SHAPES[env.shape].grasp_width  # the object's extent across the push
        arm_qpos = env.data.qpos[env.scene.ids.arm_qpos]
        self.planner.follow(push_segments(self.planner, obj[:2], env.zone_center, reach), env.ee_position(), arm_qpos)

    def select_action(self, observation: dict | None = None) -> np.ndarray:
        return self.planner.next_action()
