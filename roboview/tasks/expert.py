"""The scripted expert of RoboView's own scene: the privileged policy every task's `plan` drives."""

from __future__ import annotations

import numpy as np

from roboview.sim.control import EE_CONTROLS, JointToEE
from roboview.sim.motion import MotionPlanner, yaw_of
from roboview.sim.scene import SHAPES
from roboview.tasks.env import TaskEnv
from roboview.tasks.world import WorldExpert


class ScriptedExpert(WorldExpert):
    """Privileged: reads the object's true pose and the target's, then follows the task's `plan`.

    It solves every context at baseline visuals, so a benchmark that biases it is broken. It plans joint
    targets; an env with end-effector control gets the EE action commanding the same pinch pose
    (`JointToEE`: the targets' forward kinematics for ee_abs, their difference from the EE state for ee_delta).
    """

    def __init__(self, env: TaskEnv) -> None:
        super().__init__(env)
        self.planner = MotionPlanner(env.model)
        self._to_ee = (
            JointToEE(env.model, env.control, self.planner.ik) if env.control in EE_CONTROLS else None
        )

    def reset(self) -> None:
        """Plan from the current (just reset) simulator state."""
        env = self.env
        obj_pos, obj_quat = env.object_pose()
        shape = SHAPES[env.shape]
        env.plan(
            self.planner,
            obj_pos,
            yaw_of(obj_quat),
            shape.symmetry,
            shape.grasp_width,
            env.target_xy(),
            env.data.qpos[env.scene.ids.arm_qpos],
            ee_pos=env.ee_position(),
        )

    def select_action(self, observation: dict | None = None) -> np.ndarray:
        action = self.planner.next_action()
        return action if self._to_ee is None else self._to_ee(action, self.env.ee_state())
