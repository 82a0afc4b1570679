"""The scripted expert: privileged state + the pick-and-place motion planner.

At reset it reads the object's true pose from the simulator (the only agent allowed to) and hands
it to `PickPlacePlanner` (roboview_data.sim.motion), whose actions it returns step by step. It
solves every context at baseline visuals, so a benchmark that biases it is broken.
"""

from __future__ import annotations

import numpy as np

from roboview_data.sim.env import PickPlaceEnv
from roboview_data.sim.motion import PickPlacePlanner, yaw_of
from roboview_data.sim.scene import SHAPES


class ScriptedExpert:
    """Ground-truth object pose in, env actions out."""

    name = "expert"

    def __init__(self, env: PickPlaceEnv) -> None:
        self.env = env
        self.planner = PickPlacePlanner(env.model)

    def reset(self) -> None:
        """Plan from the current (just reset) simulator state, reading the object's true pose."""
        obj_pos, obj_quat = self.env.object_pose()
        arm_qpos = self.env.data.qpos[self.env.scene.ids.arm_qpos]
        self.planner.plan(obj_pos, yaw_of(obj_quat), SHAPES[self.env.shape].symmetry, arm_qpos,
                          ee_pos=self.env.ee_position())

    def select_action(self, observation: dict | None = None) -> np.ndarray:
        return self.planner.next_action()
