"""A privileged scripted expert for LIBERO's pick-and-place suites (`libero_object`, `libero_spatial`).

Why: a policy-free reference that solves the baseline scenes tells a visual-bias study whether a failure under a
visual factor comes from the policy or from the scene (the expert reads no pixels, so a factor cannot move it).

What: `LiberoExpert(world).select_action(obs)` returns LIBERO's 7-D action (OSC_POSE delta: position / 0.05 m,
axis-angle / 0.5 rad, world frame; gripper -1 open, +1 close) from the TRUE MuJoCo state: object poses, collision
boxes and the grip site. What to pick and where to put it come from LIBERO's own parsed goal
(`parsed_problem["goal_state"]`: `(In obj basket_1_contain_region)` or `(On bowl plate_1)`), never from the task name.

The plan is a small state machine: above the grasp point → descend → close → lift → carry over the target → lower
→ open → retreat. Positions follow a proportional law (clipped to [-1, 1]); orientation is held at the start pose
turned by a grasp yaw. The grasp is the cheapest of 36 candidates (`grasp_candidates`): an object narrower than the
fingers' span is pinched across its middle (boxes across their narrow side), a wider one (a bowl) by its rim with the
fingers closing radially; a candidate whose hand or fingers would land on a neighbour (every object and fixture geom,
as vertical prisms) is raised or costed out, and rims nearer the robot win (a stretched arm is an OSC singularity).
Travel rises first, then moves level over everything on the way (hand and carried object both clear it). A grasp
that does not hold (the object stays down, or slips from the hand while carried) starts over from "above".
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import numpy as np

from roboview.libero.suites import check_suite

EXPERT_SUITES = ("libero_object", "libero_spatial")
POS_SCALE = 0.05  # m per unit action (robosuite OSC_POSE output_max)
ROT_SCALE = 0.5  # rad per unit action
OPEN, CLOSE = -1.0, 1.0
GRIPPER_STEPS = 10  # control steps to wait while the fingers close / open (≈ 8 for a full swing)
MAX_OPENING = 0.07  # m: the Panda's fingers span 8 cm; a wider object is pinched by its rim (a bowl)
HAND = (0.105, 0.035)  # half length along the closing axis, half width across it, of the hand's footprint (m)
HAND_ABOVE = 0.03  # the hand's underside above the grip site (m)
FINGERS = (0.05, 0.012)  # the open fingers' footprint (m)
FINGER_BELOW = 0.015  # the fingertips below the grip site (m)
SUPPORT_SPAN = 0.4  # a geom wider than this (m) is the table or the floor: never an obstacle
CLEARANCE = 0.03  # kept between the hand or the carried object and what they pass over (m)
STALL = 0.002  # m in 5 steps: the arm stopped (contact or reach)
REACH_COST = 1.0  # grasp cost per m along +x (away from the robot's base: nearer full stretch, a singularity)


@dataclass(frozen=True)
class Goal:
    """What LIBERO's goal asks: put `pick` in/on `target`; `region` is the site of an `In` goal (else None)."""

    relation: str
    pick: str
    target: str
    region: str | None


@dataclass(frozen=True)
class Grasp:
    """A grasp: grip-site position, the fingers' closing direction (unit xy) and its cost (lower is better)."""

    pos: np.ndarray
    closing: np.ndarray
    cost: float


def goal_of(inner) -> Goal:
    """The single pick-and-place predicate of LIBERO's parsed goal (`In obj region` or `On obj other`)."""
    states = inner.parsed_problem["goal_state"]
    if len(states) != 1 or states[0][0] not in ("in", "on") or len(states[0]) != 3:
        raise ValueError(
            f"goal {states!r} is not one pick-and-place predicate; allowed: (In a r) or (On a b)"
        )
    relation, pick, where = states[0]
    if where in inner.object_sites_dict:
        return Goal(relation, pick, inner.object_sites_dict[where].parent_name, where)
    return Goal(relation, pick, where, None)


# ---- true geometry from MuJoCo -------------------------------------------------------------------------------
def geom_ids(model: mujoco.MjModel, root_body: str) -> np.ndarray:
    """Collision geoms of the body tree rooted at `root_body` (an object's or a fixture's root body)."""
    root = model.body(root_body).id
    bodies = [b for b in range(model.nbody) if _under(model, b, root)]
    geoms = np.flatnonzero(np.isin(model.geom_bodyid, bodies))
    collide = (model.geom_contype[geoms] != 0) | (model.geom_conaffinity[geoms] != 0)
    return geoms[collide] if collide.any() else geoms


def _under(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = model.body_parentid[body]
    return False


def box_corners(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray) -> np.ndarray:
    """World-frame corners, (n, 8, 3), of the geoms' local bounding boxes (MuJoCo's `geom_aabb`)."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    local = model.geom_aabb[geoms, None, :3] + signs[None] * model.geom_aabb[geoms, None, 3:]
    rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
    return data.geom_xpos[geoms, None, :] + np.einsum("nij,nkj->nki", rot, local)


@dataclass(frozen=True)
class Prisms:
    """Geoms as vertical prisms: xy rectangles (center, axes, half sizes) from z_low to z_top."""

    center: np.ndarray  # (n, 2)
    axes: np.ndarray  # (n, 2, 2): rows are the rectangle's unit axes
    half: np.ndarray  # (n, 2)
    z: np.ndarray  # (n, 2): low, top

    @classmethod
    def of(cls, corners: np.ndarray, rot: np.ndarray) -> Prisms:
        """From (n, 8, 3) corners and (n, 3, 3) geom frames: the two most horizontal local axes span the rectangle."""
        keep = np.argsort(np.abs(rot[:, 2, :]), axis=1)[:, :2]
        axes = np.take_along_axis(rot[:, :2, :], keep[:, None, :], axis=2).transpose(0, 2, 1)
        axes = axes / np.maximum(np.linalg.norm(axes, axis=2, keepdims=True), 1e-9)
        center = corners[:, :, :2].mean(1)
        half = np.abs(np.einsum("nkd,nad->nka", corners[:, :, :2] - center[:, None], axes)).max(1)
        return cls(center, axes, half, np.stack([corners[:, :, 2].min(1), corners[:, :, 2].max(1)], 1))

    def top_over(self, points: np.ndarray, margin: float = 0.0) -> float:
        """Highest top among the prisms any of the xy `points` falls in (grown by `margin`); -inf if none."""
        if not len(self.center):
            return -np.inf
        proj = np.einsum("nkd,nad->nka", points[None] - self.center[:, None], self.axes)
        hit = (np.abs(proj) <= self.half[:, None] + margin).all(2).any(1)
        return float(self.z[hit, 1].max()) if hit.any() else -np.inf


def rect_points(
    center: np.ndarray, axis: np.ndarray, half: tuple[float, float], step: float = 0.01
) -> np.ndarray:
    """xy sample points of a rectangle centered at `center`, `half[0]` along unit `axis`, `half[1]` across."""
    across = np.array([-axis[1], axis[0]])
    u = np.linspace(-half[0], half[0], max(2, int(2 * half[0] / step) + 1))
    v = np.linspace(-half[1], half[1], max(2, int(2 * half[1] / step) + 1))
    return center + u[:, None, None] * axis + v[None, :, None] * across


def corridor_points(start: np.ndarray, end: np.ndarray, half_width: float) -> np.ndarray:
    """xy sample points of the band of half width `half_width` swept from `start` to `end` (both ends included)."""
    length = float(np.linalg.norm(end - start))
    axis = (end - start) / length if length > 1e-6 else np.array([1.0, 0.0])
    return rect_points((start + end) / 2, axis, (length / 2 + half_width, half_width), 0.01).reshape(-1, 2)


def axis_angle(rot: np.ndarray) -> np.ndarray:
    """Axis-angle vector of rotation matrix `rot`."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot).reshape(9))
    if quat[0] < 0:
        quat = -quat
    sin = np.linalg.norm(quat[1:])
    if sin < 1e-9:
        return np.zeros(3)
    return quat[1:] / sin * 2.0 * np.arctan2(sin, quat[0])


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def signed_yaw(frm: np.ndarray, to: np.ndarray) -> float:
    """Yaw turning closing axis `frm` onto `to`, in [-π/2, π/2) (the gripper is symmetric under a half turn)."""
    yaw = np.arctan2(to[1], to[0]) - np.arctan2(frm[1], frm[0])
    return float((yaw + np.pi / 2) % np.pi - np.pi / 2)


# ---- grasp planning ------------------------------------------------------------------------------------------
def grasp_candidates(pick: np.ndarray, obstacles: Prisms, closing0: np.ndarray) -> list[Grasp]:
    """Grasps of an object with corners `pick` (n, 8, 3) among `obstacles`, every 10° of closing direction.

    An object narrower than MAX_OPENING along some direction is pinched across its middle, a wider one (a bowl) by
    its rim with the fingers closing radially. A grasp whose fingers or hand would land on an obstacle is raised
    (while it still holds the object) or costed out; turning far from the start yaw and a wide pinch cost a little.
    """
    pts = pick.reshape(-1, 3)
    lo, hi = pts.min(0), pts.max(0)
    center, top, bottom = (lo + hi) / 2, hi[2], lo[2]
    angles = np.deg2rad(np.arange(0, 360, 10))
    axes = np.stack([np.cos(angles), np.sin(angles)], 1)
    widths = np.ptp(pts[:, :2] @ axes.T, axis=0)
    pinch = widths.min() <= MAX_OPENING  # else: a rim grasp
    out = []
    for angle, axis, width in zip(angles, axes, widths, strict=True):
        proj = pts[:, :2] @ axis
        if pinch and width > MAX_OPENING:
            continue
        if pinch:
            if angle >= np.pi:
                continue  # a half turn of a middle pinch is the same grasp
            xy, z = center[:2], max(top - 0.035, bottom + 0.015, (top + bottom) / 2)
        else:
            xy, z = center[:2] + axis * (proj.max() - center[:2] @ axis - 0.015), top - 0.02
        hand = (
            obstacles.top_over(rect_points(xy, axis, HAND).reshape(-1, 2), 0.005) + CLEARANCE / 3 - HAND_ABOVE
        )
        fingers = obstacles.top_over(rect_points(xy, axis, FINGERS).reshape(-1, 2), 0.005) + FINGER_BELOW
        z = max(z, hand, fingers)
        blocked = max(0.0, z - (top - 0.008))
        cost = (
            abs(signed_yaw(closing0, axis)) * 0.02 + (width if width <= MAX_OPENING else 0.0) + 10 * blocked
        )
        out.append(
            Grasp(np.array([*xy, z]), axis, cost + REACH_COST * xy[0])
        )  # nearer the robot: more reach left
    return out


class LiberoExpert:
    """Scripted pick-and-place from privileged state for one `LiberoWorld` of `libero_object`/`libero_spatial`.

    Call `reset()` after each `world.reset()`, then `select_action(obs)` every step (`obs` is not read: no image is
    rendered). `phase` names the current stage; `attempts` counts re-grasps.
    """

    def __init__(self, world, *, gain: float = 1.0) -> None:
        suite = check_suite(world.task.suite)
        if suite not in EXPERT_SUITES:
            raise ValueError(
                f"LiberoExpert does not script suite {suite!r}; allowed: {', '.join(EXPERT_SUITES)}"
            )
        self.world, self.gain = world, gain
        self.goal: Goal | None = None
        self.reset()

    # ---- state readers -------------------------------------------------------------------------------------
    @property
    def inner(self):
        return self.world.inner

    def eef(self) -> np.ndarray:
        return np.array(self.inner.sim.data.site_xpos[self.inner.robots[0].eef_site_id])

    def eef_rot(self) -> np.ndarray:
        return np.array(self.inner.sim.data.site_xmat[self.inner.robots[0].eef_site_id]).reshape(3, 3)

    def corners(self, name: str) -> np.ndarray:
        """(n, 8, 3) world corners of object or fixture `name`'s collision geoms."""
        if name not in self._geoms:
            self._geoms[name] = geom_ids(self.world.model, self.inner.get_object(name).root_body)
        return box_corners(self.world.model, self.world.data, self._geoms[name])

    def body_pos(self, name: str) -> np.ndarray:
        return np.array(self.inner.sim.data.body_xpos[self.inner.obj_body_id[name]])

    def obstacles(self, skip: tuple[str, ...] = ()) -> Prisms:
        """Every object and fixture geom but those of `skip` and the table/floor, as prisms."""
        names = [n for n in (*self.inner.objects_dict, *self.inner.fixtures_dict) if n not in skip]
        corners, rots = [], []
        for name in names:
            c = self.corners(name)
            geoms = self._geoms[name]
            span = np.ptp(c[:, :, :2], axis=1).max(1)
            corners.append(c[span < SUPPORT_SPAN])
            rots.append(self.world.data.geom_xmat[geoms[span < SUPPORT_SPAN]].reshape(-1, 3, 3))
        return Prisms.of(np.concatenate(corners), np.concatenate(rots))

    # ---- episode -------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Start a new plan from the world's current (just reset) state."""
        self._geoms: dict[str, np.ndarray] = {}
        self.goal = goal_of(self.inner)
        self.phase, self._phase_steps, self.steps, self.attempts = "above", 0, 0, 0
        self._rot0 = self.eef_rot()
        self._history: list[np.ndarray] = []
        self._plan_grasp()

    def _plan_grasp(self) -> None:
        """The cheapest grasp of the pick object as it lies now, and the hover point above it."""
        closing0 = self._rot0[:2, 0] / np.linalg.norm(
            self._rot0[:2, 0]
        )  # the fingers close along the site's x
        self._around_pick = self.obstacles(skip=(self.goal.pick,))
        best = min(
            grasp_candidates(self.corners(self.goal.pick), self._around_pick, closing0), key=lambda g: g.cost
        )
        self._yaw_rot = yaw_matrix(signed_yaw(closing0, best.closing)) @ self._rot0
        top = self.corners(self.goal.pick)[:, :, 2].max()
        self._grasp = best.pos
        self._hover = best.pos + np.array([0, 0, max(0.08, top - best.pos[2] + 0.05)])
        self._pick_z0 = self.body_pos(self.goal.pick)[2]

    # ---- control -------------------------------------------------------------------------------------------
    def select_action(self, obs=None) -> np.ndarray:
        """LIBERO's 7-D action for the current state (`obs` is accepted for the policy API and not read)."""
        self._history = [*self._history[-5:], self.eef()]
        target, grip, next_phase = getattr(self, f"_{self.phase}")()
        action = np.zeros(7, np.float32)
        if target is not None:
            action[:3] = np.clip(self.gain * (target - self.eef()) / POS_SCALE, -1.0, 1.0)
        action[3:6] = np.clip(axis_angle(self._yaw_rot @ self.eef_rot().T) / ROT_SCALE, -1.0, 1.0)
        action[6] = grip
        self.steps += 1
        self._phase_steps += 1
        if next_phase is not None and next_phase != self.phase:
            self.phase, self._phase_steps = next_phase, 0
        return action

    def _stalled(self) -> bool:
        """The hand moved less than STALL over the last 5 steps (after 5 steps in the phase)."""
        return self._phase_steps > 5 and np.linalg.norm(self._history[-1] - self._history[0]) < STALL

    def _transit(
        self, goal: np.ndarray, hang: float = 0.0, radius: float = 0.0, lead: np.ndarray | None = None
    ):
        """Waypoint to `goal` over every obstacle: rise in place first, then travel level. With a load hanging
        `hang` below the hand (radius `radius`, centered `lead` from the hand in xy) the load clears them too."""
        eef = self.eef()
        lead = np.zeros(2) if lead is None else lead
        hand = self._route.top_over(corridor_points(eef[:2], goal[:2], 0.06), 0.0) + HAND_ABOVE + CLEARANCE
        load = self._route.top_over(corridor_points(eef[:2] - lead, goal[:2] - lead, radius), 0.0)
        level = max(goal[2], hand, load + hang + CLEARANCE)
        if np.linalg.norm(goal[:2] - eef[:2]) < 0.01:
            return np.array([*goal[:2], level]), True
        if eef[2] < level - 0.02:
            return np.array([*eef[:2], level]), False
        return np.array([*goal[:2], level]), False

    def _above(self):
        if self._phase_steps == 0:
            self._route = self.obstacles(skip=(self.goal.pick,))
        target, arrived = self._transit(self._hover)
        turned = np.linalg.norm(axis_angle(self._yaw_rot @ self.eef_rot().T)) < 0.1
        done = arrived and turned and abs(self.eef()[2] - target[2]) < 0.03
        return target, OPEN, "descend" if done else None

    def _descend(self):
        done = np.linalg.norm(self._grasp - self.eef()) < 0.006 or self._stalled() or self._phase_steps > 40
        return self._grasp, OPEN, "close" if done else None

    def _close(self):
        return self._grasp, CLOSE, "lift" if self._phase_steps >= GRIPPER_STEPS else None

    def _lift(self):
        target = self._grasp + np.array([0, 0, 0.06])
        if self.eef()[2] < target[2] - 0.01 and self._phase_steps < 30:
            return target, CLOSE, None
        if self.body_pos(self.goal.pick)[2] - self._pick_z0 < 0.03:
            return self._retry()
        self._hold = self.eef() - self.body_pos(self.goal.pick)
        self._route = self.obstacles(skip=(self.goal.pick,))
        return target, CLOSE, "carry"

    def _carry(self):
        if np.linalg.norm(self.eef() - self.body_pos(self.goal.pick) - self._hold) > 0.03:
            return self._retry()
        pick = self.corners(self.goal.pick).reshape(-1, 3)
        lead = self.body_pos(self.goal.pick)[:2] - self.eef()[:2]
        hang = self.eef()[2] - pick[:, 2].min()
        radius = float(np.ptp(pick[:, :2], axis=0).max() / 2)
        goal_xy = self._place_xy() - lead
        level = self._release_z() + hang + 0.02
        target, arrived = self._transit(np.array([*goal_xy, level]), hang, radius, lead)
        miss = np.linalg.norm(self._place_xy() - self.body_pos(self.goal.pick)[:2])
        done = (arrived and miss < 0.012) or (miss < 0.025 and self._stalled())
        return target, CLOSE, "lower" if done else None

    def _lower(self):
        bottom = self.corners(self.goal.pick)[:, :, 2].min()
        drop = self._release_z() - bottom
        lead = self.body_pos(self.goal.pick)[:2] - self.eef()[:2]
        target = np.array([*(self._place_xy() - lead), self.eef()[2] + drop])
        done = drop > -0.005 or self._stalled() or self._phase_steps > 40
        return target, CLOSE, "release" if done else None

    def _release(self):
        if self._phase_steps == 0:
            self._retreat_to = self.eef() + np.array([0, 0, 0.10])
        return self.eef(), OPEN, "retreat" if self._phase_steps >= GRIPPER_STEPS else None

    def _retreat(self):
        done = np.linalg.norm(self._retreat_to - self.eef()) < 0.02 or self._phase_steps > 30
        return self._retreat_to, OPEN, "done" if done else None

    def _done(self):
        return None, OPEN, None

    def _retry(self):
        self.attempts += 1
        self._plan_grasp()
        return self.eef() + np.array([0, 0, 0.05]), OPEN, "above"

    # ---- placement -----------------------------------------------------------------------------------------
    def _place_xy(self) -> np.ndarray:
        goal = self.goal
        if goal.region is not None:
            return np.array(self.inner.sim.data.get_site_xpos(goal.region)[:2])
        return self.body_pos(goal.target)[:2]

    def _release_z(self) -> float:
        """Where the object's bottom is let go: low in a container (`In`), just above the support (`On`)."""
        target = self.corners(self.goal.target)[:, :, 2]
        return float(target.min() + 0.03 if self.goal.relation == "in" else target.max() + 0.01)


@dataclass(frozen=True)
class EpisodeResult:
    """One expert rollout: LIBERO's success, steps taken, the phase it ended in, re-grasps, rollout seconds."""

    success: bool
    steps: int
    phase: str
    attempts: int
    seconds: float


def run_episode(world, max_steps: int, seed: int = 0) -> EpisodeResult:
    """Reset `world` (LeRobot's reset with `seed`) and roll the expert out until LIBERO's success or `max_steps`.

    No image is read, so no frame is rendered; `seconds` covers the rollout, not the reset."""
    world.reset(seed)
    expert = LiberoExpert(world)
    start = time.perf_counter()
    success, steps = False, 0
    while steps < max_steps and not success:
        _, _, _, _, info = world.step(expert.select_action())
        steps += 1
        success = bool(info["is_success"])
    return EpisodeResult(success, steps, expert.phase, expert.attempts, time.perf_counter() - start)
