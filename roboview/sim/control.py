"""End-effector control of the Panda: EE commands → the arm's joint position targets, and the EE state.

The arm has joint position servos, so every control mode ends in 7 joint targets + a gripper closure, held
for one control period. `joint` commands them directly; the two end-effector modes go through
`EEController`, which solves damped-least-squares inverse kinematics (`motion.ArmIK`, the planner's own)
for the commanded pinch-point pose once per control step:

- `ee_delta` (7, each in [-1, 1]; LIBERO / robosuite OSC_POSE): position delta × 0.05 m and rotation delta
  as axis-angle × 0.5 rad, both in the robot base frame and relative to the *current* pinch pose
  (target R = exp(δ) · R_now), then the gripper (+1 close, −1 open).
- `ee_abs` (7): target pinch position (m) and orientation as axis-angle (rad), base frame, then the gripper.

The EE state (`EndEffector.state`, 8) is LIBERO's "eef_pos3_axisangle3_gripper2": pinch position, its
orientation as axis-angle, and the two fingers' openings. The Robotiq 2F-85 has one driven joint, so the two
values are each finger pad's inner face, measured from the pinch point along the closing axis (m): about
+0.0426 and −0.0426 fully open (the 85 mm stroke), 0 and 0 closed — the sign convention of LIBERO's two
Panda finger joints (±0.04 open). Everything here is a pure function of the joint reading and the action:
the same actions give bit-identical trajectories.
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.sim.motion import ArmIK
from roboview.sim.scene import PANDA_PREFIX, SceneIds

CONTROLS = ("joint", "ee_delta", "ee_abs")
EE_CONTROLS = ("ee_delta", "ee_abs")
# ee_delta's scales (robosuite OSC_POSE's output_max, as LIBERO trains with): one unit of action is this much.
POSITION_SCALE_M = 0.05
ROTATION_SCALE_RAD = 0.5
# ee_abs's bounds on the target position (m, base frame): a box around the arm's reach (0.855 m).
ABS_POSITION_LOW = (-1.0, -1.0, -0.5)
ABS_POSITION_HIGH = (1.0, 1.0, 1.5)
EE_STATE_NAMES = ("eef_x", "eef_y", "eef_z", "eef_ax", "eef_ay", "eef_az", "finger_right", "finger_left")
EE_ACTION_NAMES = {
    "ee_delta": ("delta_x", "delta_y", "delta_z", "delta_ax", "delta_ay", "delta_az", "gripper_close"),
    "ee_abs": ("target_x", "target_y", "target_z", "target_ax", "target_ay", "target_az", "gripper_close"),
}
ARM_BASE_BODY = f"{PANDA_PREFIX}link0"
# The pad geoms whose inner faces give the finger openings (right finger first, as LIBERO's joint 1).
FINGER_PADS = (f"{PANDA_PREFIX}right_pad1", f"{PANDA_PREFIX}left_pad1")


def check_control(control: str) -> str:
    """`control` if it is one of CONTROLS, else ValueError naming the allowed values."""
    if control not in CONTROLS:
        raise ValueError(f"unknown control {control!r}; allowed: {', '.join(CONTROLS)}")
    return control


def ee_action_space_bounds(control: str) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) float32 of an end-effector control's 7-d action."""
    if control == "ee_delta":
        return -np.ones(7, np.float32), np.ones(7, np.float32)
    if control == "ee_abs":
        low = np.array([*ABS_POSITION_LOW, -np.pi, -np.pi, -np.pi, -1.0], np.float32)
        high = np.array([*ABS_POSITION_HIGH, np.pi, np.pi, np.pi, 1.0], np.float32)
        return low, high
    raise ValueError(f"not an end-effector control: {control!r}; allowed: {', '.join(EE_CONTROLS)}")


def axis_angle(rotation: np.ndarray) -> np.ndarray:
    """Axis-angle (3, rad; angle in [0, π]) of a 3×3 rotation matrix, as robosuite's quat2axisangle."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotation, dtype=np.float64).ravel())
    if quat[0] < 0:
        quat = -quat
    sin_half = np.linalg.norm(quat[1:])
    if sin_half < 1e-12:
        return np.zeros(3)
    return quat[1:] * (2.0 * np.arctan2(sin_half, quat[0]) / sin_half)


def rotation_matrix(rotvec: np.ndarray) -> np.ndarray:
    """3×3 rotation matrix of an axis-angle vector (rad)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(rotvec))
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    if angle > 0.0:
        mujoco.mju_axisAngle2Quat(quat, rotvec / angle, angle)
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def gripper_closure(command: float) -> float:
    """EE gripper command (+1 close, −1 open) → the joint action's closure (0 open … 1 closed)."""
    return (float(command) + 1.0) / 2.0


class EndEffector:
    """The pinch point's pose and the finger openings, from a joint reading (its own scratch `MjData`).

    Reading the forward kinematics of `qpos` on scratch data, never the simulation's own, keeps the
    simulation's derived quantities (what the renderer draws) exactly as stepping left them.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self._site = SceneIds.lookup(model).pinch_site
        self._pads = [model.geom(name).id for name in FINGER_PADS]
        self._pad_half = float(model.geom_size[self._pads[0], 1])  # pad thickness / 2 along the closing axis
        # The arm base is welded to the world: its pose is the model's, whatever the episode.
        mujoco.mj_kinematics(model, self.data)
        base = model.body(ARM_BASE_BODY).id
        self.base_pos = self.data.xpos[base].copy()
        self.base_rot = self.data.xmat[base].reshape(3, 3).copy()

    def to_base(self, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A world pose in the robot base frame."""
        return self.base_rot.T @ (pos - self.base_pos), self.base_rot.T @ rot

    def to_world(self, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A base-frame pose in the world frame."""
        return self.base_pos + self.base_rot @ pos, self.base_rot @ rot

    def _forward(self, qpos: np.ndarray) -> None:
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)

    def pose(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of the pinch site for a full `qpos`."""
        self._forward(qpos)
        return self.data.site_xpos[self._site].copy(), self.data.site_xmat[self._site].reshape(3, 3).copy()

    def state(self, qpos: np.ndarray) -> np.ndarray:
        """float32 (8): pinch position (m, base frame), orientation axis-angle (rad), finger openings (m)."""
        self._forward(qpos)
        pos = self.data.site_xpos[self._site]
        rot = self.data.site_xmat[self._site].reshape(3, 3)
        closing_axis = rot[:, 1]
        right, left = ((self.data.geom_xpos[g] - pos) @ closing_axis for g in self._pads)
        pos_b, rot_b = self.to_base(pos, rot)
        fingers = (right - self._pad_half, left + self._pad_half)
        return np.concatenate([pos_b, axis_angle(rot_b), fingers]).astype(np.float32)


class EEController:
    """An end-effector command → the arm's 7 joint position targets (+ gripper closure), once per control step.

    Damped-least-squares IK (`ArmIK`) from the current joints to the commanded pinch pose: the servos then
    track the targets for the control period. The targets stay 1 mrad inside the joint range.
    """

    def __init__(self, model: mujoco.MjModel, control: str, end_effector: EndEffector | None = None) -> None:
        if check_control(control) not in EE_CONTROLS:
            raise ValueError(f"EEController runs {', '.join(EE_CONTROLS)}, not {control!r}")
        self.control = control
        self.ik = ArmIK(model)
        self.end_effector = end_effector or EndEffector(model)  # the env's own, where it has one
        self._arm = SceneIds.lookup(model).arm_qpos

    def target_pose(self, qpos: np.ndarray, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The commanded pinch pose (world position, rotation matrix) for `action` at joint reading `qpos`."""
        ee = self.end_effector
        if self.control == "ee_delta":
            pos, rot = ee.pose(qpos)
            step = ee.base_rot @ (POSITION_SCALE_M * np.asarray(action[:3], np.float64))
            turn = ee.base_rot @ (ROTATION_SCALE_RAD * np.asarray(action[3:6], np.float64))
            return pos + step, rotation_matrix(turn) @ rot
        return ee.to_world(np.asarray(action[:3], np.float64), rotation_matrix(action[3:6]))

    def joint_action(self, qpos: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The joint action (8: 7 targets, rad, + closure in [0, 1]) for an EE `action` at joint reading `qpos`."""
        target, r_target = self.target_pose(qpos, action)
        q = self.ik.solve(target, r_target, np.asarray(qpos[self._arm], np.float64))
        return np.append(q, np.clip(gripper_closure(action[6]), 0.0, 1.0))


class JointToEE:
    """A joint action (7 targets + closure) → the EE action that commands the same pinch pose.

    For agents that plan joint targets (the scripted expert, the vision and VLM agents): `ee_abs` is the
    forward kinematics of the targets; `ee_delta` their difference from the current EE state (the
    observation's), scaled and clipped to [-1, 1] as the action space demands. The gripper maps 0 → −1
    (open), 1 → +1 (close).
    """

    def __init__(self, model: mujoco.MjModel, control: str, ik: ArmIK | None = None) -> None:
        if check_control(control) not in EE_CONTROLS:
            raise ValueError(f"JointToEE converts to {', '.join(EE_CONTROLS)}, not {control!r}")
        self.control = control
        self.ik = ik or ArmIK(
            model
        )  # a planner's own, where it has one (its forward kinematics is all we use)
        self.end_effector = EndEffector(model)

    def __call__(self, joint_action: np.ndarray, ee_state: np.ndarray) -> np.ndarray:
        pos, rot = self.end_effector.to_base(*self.ik.pinch_pose(np.asarray(joint_action[:7], np.float64)))
        grip = 2.0 * float(joint_action[7]) - 1.0
        if self.control == "ee_abs":
            return np.array([*pos, *axis_angle(rot), grip], np.float32)
        ee_state = np.asarray(ee_state, np.float64)
        step = (pos - ee_state[:3]) / POSITION_SCALE_M
        turn = axis_angle(rot @ rotation_matrix(ee_state[3:6]).T) / ROTATION_SCALE_RAD
        return np.clip(np.array([*step, *turn, grip]), -1.0, 1.0).astype(np.float32)
