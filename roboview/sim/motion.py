"""Pick-and-place motion planner: minimum-jerk Cartesian waypoints + damped-least-squares IK.

`MotionPlanner.plan` takes an object pose (center, heading, rotational symmetry) and where to
release it, and lays out the gripper's pinch-point path through fixed waypoints (hover, descend, close,
lift, carry, lower, open, retreat), each segment interpolated with a minimum-jerk profile. Each
`next_action` solves inverse kinematics (position + "pointing down at yaw ψ"; `ArmIK`, which the
end-effector controller of roboview.sim.control shares) on a scratch `MjData`, so it emits exactly
the joint action: 7 joint targets + gripper command. It never reads
the simulator's object state: whoever calls `plan` decides where the object is — a task's privileged
expert (roboview.tasks) from ground truth, the `vision` policy from perception.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from roboview.sim.scene import HOME_QPOS, SceneIds

# Heights (m) of the pinch point: hover above the object, carry over the target.
HOVER_Z = 0.12
CARRY_Z = 0.20
# The pinch site sits between the fingertips; grasp a little above the object's center.
GRASP_OFFSET_Z = 0.004


@dataclass(frozen=True)
class Segment:
    """Move the pinch point to `target` (yaw `yaw`) over `steps` control steps with the gripper at `grip`."""

    target: np.ndarray
    yaw: float
    steps: int
    grip: float


def yaw_of(quat: np.ndarray) -> float:
    """Heading (rad, about world z) of a [w, x, y, z] quaternion."""
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _min_jerk(s: float) -> float:
    return s**3 * (10 - 15 * s + 6 * s * s)


class ArmIK:
    """Damped-least-squares inverse kinematics of the pinch point, on a scratch `MjData` of `model`.

    Each iteration takes the pinch site's Jacobian (`mj_jacSite`) and steps
    dq = Jᵀ (J Jᵀ + λI)⁻¹ e toward the 6-d pose error e, plus a gentle pull toward the home posture in the
    Jacobian's null space so the redundant elbow does not drift; the joints are clipped to their range
    (1 mrad inside it) after every step. It never touches the simulation's own data.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        ids = SceneIds.lookup(model)
        self._qadr, self._dof, self._site = ids.arm_qpos, ids.arm_dof, ids.pinch_site
        self._jac_p = np.zeros((3, model.nv))
        self._jac_r = np.zeros((3, model.nv))
        lo_hi = ids.arm_range
        self.q_lo, self.q_hi = lo_hi[:, 0] + 1e-3, lo_hi[:, 1] - 1e-3
        # Orientation of the pinch site at the home pose (pointing straight down, yaw 0).
        self.home_rotation = self.pinch_pose(HOME_QPOS)[1]

    def pinch_pose(self, arm_qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World position and 3×3 rotation of the pinch site for a joint reading (forward kinematics)."""
        self.data.qpos[self._qadr] = arm_qpos
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.site_xpos[self._site].copy(), self.data.site_xmat[self._site].reshape(3, 3).copy()

    def solve(
        self,
        target: np.ndarray,
        r_target: np.ndarray,
        q0: np.ndarray,
        iters: int = 30,
        damping: float = 1e-4,
    ) -> np.ndarray:
        """Arm joints (7) putting the pinch site at `target` (world, m) with rotation `r_target` (3×3, world),
        iterated from `q0`; stops early within 0.1 mm and 1 mrad."""
        data, q = self.data, q0.copy()
        for _ in range(iters):
            data.qpos[self._qadr] = q
            mujoco.mj_kinematics(self.model, data)
            mujoco.mj_comPos(self.model, data)
            r_now = data.site_xmat[self._site].reshape(3, 3)
            err_p = target - data.site_xpos[self._site]
            err_r = 0.5 * sum(np.cross(r_now[:, i], r_target[:, i]) for i in range(3))
            err = np.concatenate([err_p, err_r])
            if np.linalg.norm(err_p) < 1e-4 and np.linalg.norm(err_r) < 1e-3:
                break
            mujoco.mj_jacSite(self.model, data, self._jac_p, self._jac_r, self._site)
            jac = np.vstack([self._jac_p[:, self._dof], self._jac_r[:, self._dof]])
            dq = jac.T @ np.linalg.solve(jac @ jac.T + damping * np.eye(6), err)
            # Pull gently toward the home posture in the null space to avoid drifting elbows.
            null = np.eye(7) - np.linalg.pinv(jac) @ jac
            dq += null @ (0.05 * (HOME_QPOS - q))
            q = np.clip(q + dq, self.q_lo, self.q_hi)
        return q


class MotionPlanner:
    """Plans a grasp-carry-release path for a given object pose and follows it, one action per step."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model  # the robot's kinematics: the scene compiled at defaults is enough
        self.ik = ArmIK(model)
        self._r_home = self.ik.home_rotation
        self._home_finger_yaw = float(np.arctan2(self._r_home[1, 1], self._r_home[0, 1]))
        self._plan: list[tuple[np.ndarray, float, float]] = []
        self._t = 0
        self._q = HOME_QPOS.copy()

    def plan(
        self,
        obj_pos: np.ndarray,
        obj_yaw: float,
        symmetry: float,
        arm_qpos: np.ndarray,
        box_xy: np.ndarray,
        release_z: float,
        ee_pos: np.ndarray | None = None,
    ) -> None:
        """Plan the pick-and-place for an object at `obj_pos` (its center) with heading `obj_yaw`.

        `arm_qpos` is the arm's joint reading now; `ee_pos` the pinch point's position, computed from
        it when not given. `box_xy` is where to release it (perceived, for a non-privileged agent) and
        `release_z` the pinch point's height there when the gripper opens.
        `symmetry` is the object's rotational symmetry about z (rad), which bounds the wrist turn.
        """
        q_start = np.asarray(arm_qpos, dtype=float).copy()
        start = self.pinch_position(q_start) if ee_pos is None else np.asarray(ee_pos, dtype=float).copy()
        # Fingers close along the site's y axis: align it with the object's x axis, picking the
        # symmetric equivalent nearest the current wrist yaw so the wrist turns as little as possible.
        half_turn = min(symmetry, np.pi)
        delta = obj_yaw - self._home_finger_yaw
        grasp_yaw = (delta + half_turn / 2) % half_turn - half_turn / 2
        grasp_z = obj_pos[2] + GRASP_OFFSET_Z
        above = np.array([obj_pos[0], obj_pos[1], HOVER_Z])
        box_above = np.array([box_xy[0], box_xy[1], CARRY_Z])
        box_release = np.array([box_xy[0], box_xy[1], release_z])
        segments = [
            Segment(above, grasp_yaw, 12, 0.0),
            Segment(np.array([obj_pos[0], obj_pos[1], grasp_z]), grasp_yaw, 8, 0.0),
            Segment(np.array([obj_pos[0], obj_pos[1], grasp_z]), grasp_yaw, 5, 1.0),
            Segment(np.array([obj_pos[0], obj_pos[1], CARRY_Z]), grasp_yaw, 8, 1.0),
            Segment(box_above, 0.0, 12, 1.0),
            Segment(box_release, 0.0, 5, 1.0),
            Segment(box_release, 0.0, 4, 0.0),
            Segment(box_above, 0.0, 30, 0.0),
        ]
        self.follow(segments, start, q_start)

    def finger_yaw(self, closing_axis_heading: float, symmetry: float = np.pi) -> float:
        """The plan's yaw that turns the fingers' closing axis to `closing_axis_heading` (world, rad),
        taking the equivalent (modulo `symmetry`) nearest the home wrist so the wrist turns least."""
        half_turn = min(symmetry, np.pi)
        delta = closing_axis_heading - self._home_finger_yaw
        return (delta + half_turn / 2) % half_turn - half_turn / 2

    def pinch_position(self, arm_qpos: np.ndarray) -> np.ndarray:
        """Where the pinch point is for a joint reading (forward kinematics on the scratch data)."""
        return self.ik.pinch_pose(arm_qpos)[0]

    def follow(self, segments: list[Segment], start: np.ndarray, q_start: np.ndarray) -> None:
        """Lay out `segments` from `start` (pinch point) and `q_start` (arm joints), min-jerk each."""
        self._plan = []
        pos, yaw = start, 0.0
        for seg in segments:
            for i in range(1, seg.steps + 1):
                s = _min_jerk(i / seg.steps)
                self._plan.append((pos + s * (seg.target - pos), yaw + s * (seg.yaw - yaw), seg.grip))
            pos, yaw = seg.target, seg.yaw
        self._t = 0
        self._q = q_start

    def next_action(self) -> np.ndarray:
        """The env action for the next control step of the plan (the last one repeats at its end)."""
        target, yaw, grip = self._plan[min(self._t, len(self._plan) - 1)]
        self._t += 1
        self._q = self._solve_ik(target, yaw, self._q)
        return np.append(self._q, grip).astype(np.float32)

    def _solve_ik(self, target: np.ndarray, yaw: float, q0: np.ndarray) -> np.ndarray:
        c, s = np.cos(yaw), np.sin(yaw)
        r_target = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ self._r_home
        return self.ik.solve(target, r_target, q0)
