"""The world every task shares, built once with MjSpec and varied per instance in place.

Model-level structure (robot, table, one body per object shape, cameras, plus what the task and the
visual factors add) is compiled once per env (≈1.3 s with the Panda meshes). Everything an instance varies — object rgba and
pose, which shape is on the table, camera pos/quat — is written into the compiled `MjModel`/`MjData`
in place, which costs microseconds (dm_control's initialize_episode_mjcf / initialize_episode split).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Literal

import mujoco
import numpy as np

from roboview.sim.cameras import ALL_CAMERAS, BASE_CAMERAS, CameraPose

log = logging.getLogger(__name__)

PANDA_PREFIX = "panda/"
ARM_JOINTS = tuple(f"{PANDA_PREFIX}joint{i}" for i in range(1, 8))
ARM_ACTUATORS = tuple(f"{PANDA_PREFIX}actuator{i}" for i in range(1, 8))
GRIPPER_ACTUATOR = f"{PANDA_PREFIX}fingers_actuator"
GRIPPER_JOINT = f"{PANDA_PREFIX}right_driver_joint"
GRIPPER_DRIVER_CLOSED = 0.8  # rad: right_driver_joint range upper limit (fully closed)
PINCH_SITE = f"{PANDA_PREFIX}pinch"
PAD_GEOMS = tuple(f"{PANDA_PREFIX}{side}_pad{i}" for side in ("left", "right") for i in (1, 2))

# Ready pose of the arm (rad): gripper above the workspace, pointing down, clear of all views.
HOME_QPOS = np.array([0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785])

# Servo gains of the position actuators that replace gym-hil's torque motors (N·m/rad, N·m·s/rad).
ARM_KP = np.array([4500.0, 4500.0, 3500.0, 3500.0, 2000.0, 2000.0, 2000.0])
ARM_KV = np.array([160.0, 160.0, 120.0, 120.0, 60.0, 60.0, 60.0])

TABLE_RGBA = (0.56, 0.52, 0.47, 1.0)
FLOOR_RGBA = (0.30, 0.30, 0.32, 1.0)

# Where shapes not used by the current instance wait: off the table, out of every view.
PARK_XY = np.array([-3.0, 0.0])

OBJECT_MASS = 0.06  # kg
OBJECT_FRICTION = (1.2, 0.01, 0.0005)


def hex_prism_vertices(circumradius: float, half_height: float) -> list[float]:
    angles = np.arange(6) * np.pi / 3
    ring = np.stack([circumradius * np.cos(angles), circumradius * np.sin(angles)], axis=1)
    top = np.column_stack([ring, np.full(6, half_height)])
    bottom = np.column_stack([ring, np.full(6, -half_height)])
    return np.concatenate([top, bottom]).ravel().tolist()


@dataclass(frozen=True)
class ShapeSpec:
    """A graspable solid: MuJoCo geom type, its size, and the height of its center when resting."""

    geom_type: mujoco.mjtGeom
    size: tuple[float, ...]
    half_height: float
    # Rotational symmetry about z (rad): the expert may grasp at yaw modulo this.
    symmetry: float
    # Gripper opening needed across the grasp axis (m), for the expert.
    grasp_width: float


SHAPES: dict[str, ShapeSpec] = {
    "cube": ShapeSpec(mujoco.mjtGeom.mjGEOM_BOX, (0.02, 0.02, 0.02), 0.02, np.pi / 2, 0.04),
    "cylinder": ShapeSpec(mujoco.mjtGeom.mjGEOM_CYLINDER, (0.02, 0.022, 0.0), 0.022, 2 * np.pi, 0.04),
    "hex_prism": ShapeSpec(mujoco.mjtGeom.mjGEOM_MESH, (0.0, 0.0, 0.0), 0.02, np.pi / 3, 0.04),
    "cuboid": ShapeSpec(mujoco.mjtGeom.mjGEOM_BOX, (0.016, 0.026, 0.028), 0.028, np.pi, 0.032),
}
HEX_CIRCUMRADIUS = 0.023


RenderQuality = Literal["fast", "high"]


def _panda_xml() -> str:
    path = resources.files("gym_hil") / "assets" / "panda.xml"
    if not path.is_file():
        raise FileNotFoundError(
            f"Panda model not found at {path}; install gym-hil (`make install`), which ships it."
        )
    return str(path)


def _position_servos(spec: mujoco.MjSpec) -> None:
    """Replace gym-hil's torque motors with joint position servos (keeping their torque limits)."""
    for name, kp, kv in zip(ARM_ACTUATORS, ARM_KP, ARM_KV):
        act = spec.actuator(name.removeprefix(PANDA_PREFIX))
        limit = float(act.ctrlrange[1])
        joint = spec.joint(act.target)
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.gainprm[0] = kp
        act.biasprm[:3] = [0.0, -kp, -kv]
        act.ctrlrange = joint.range
        act.forcerange = [-limit, limit]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


# Something that adds to the scene spec before it is compiled: a task's target (its receiver box, its
# marked zone), a visual factor's textures or parked bodies.
SpecAddition = Callable[[mujoco.MjSpec], None]


def build_spec(
    quality: RenderQuality = "fast", target: SpecAddition | None = None, extras: Sequence[SpecAddition] = ()
) -> mujoco.MjSpec:
    """The full scene spec: Panda + 2F-85, table, four shape bodies, cameras, plus what others add.

    `target` is the task's addition (made before the shapes), `extras` the visual factors' (after
    them, in order): compiled once, switched in place by each one's setter or applier.
    """
    spec = mujoco.MjSpec()
    spec.modelname = "roboview_pick_place"
    _set_options(spec, quality)
    world = spec.worldbody
    _add_room(world, quality)
    if target is not None:
        target(spec)
    _add_shapes(spec, world)
    for extra in extras:
        extra(spec)
    for name, pose in BASE_CAMERAS.items():
        world.add_camera(name=name, pos=list(pose.pos), quat=list(pose.quat), fovy=pose.fovy)
    _attach_panda(spec, world)
    return spec


def _set_options(spec: mujoco.MjSpec, quality: RenderQuality) -> None:
    """Physics (2 ms step, implicit damping) and rendering settings (offscreen size, headlight, quality)."""
    spec.option.timestep = 0.002
    spec.option.noslip_iterations = 3
    # Actuator damping is integrated implicitly: stiff servos stay stable at a 2 ms step.
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.visual.global_.offwidth = 640
    spec.visual.global_.offheight = 640
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.25, 0.25, 0.25]
    spec.visual.quality.offsamples = 0 if quality == "fast" else 4
    spec.visual.quality.shadowsize = 0 if quality == "fast" else 2048


def _add_room(world: mujoco.MjsBody, quality: RenderQuality) -> None:
    """The top light, the floor, the table and the parking slab where unused shapes wait."""
    world.add_light(
        name="top",
        pos=[0.4, 0.0, 2.0],
        dir=[0, 0, -1],
        diffuse=[0.45, 0.45, 0.45],
        castshadow=quality == "high",
    )
    world.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[4, 4, 0.01], pos=[0, 0, -0.75], rgba=FLOOR_RGBA
    )
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.75, 0.7, 0.02],
        pos=[0.4, 0.0, -0.02],
        rgba=TABLE_RGBA,
    )
    # Parking lot for unused shapes: a slab far from the table, never in view.
    world.add_geom(
        name="parking",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.3, 0.5, 0.02],
        pos=[PARK_XY[0], PARK_XY[1], -0.02],
        rgba=FLOOR_RGBA,
    )


def _attach_panda(spec: mujoco.MjSpec, world: mujoco.MjsBody) -> None:
    """gym-hil's Panda + 2F-85 at the origin: gravity-compensated, position servos, the wrist camera on its hand."""
    panda = mujoco.MjSpec.from_file(_panda_xml())
    for body in panda.bodies:
        body.gravcomp = 1.0
    hand = panda.body("attachment")
    hand.add_camera(name="wrist", pos=[-0.06, 0.0, 0.0], quat=[0, 1, -1, 0], fovy=70.0)
    _position_servos(panda)
    frame = world.add_frame(pos=[0, 0, 0])
    spec.attach(panda, prefix=PANDA_PREFIX, frame=frame)


def _add_shapes(spec: mujoco.MjSpec, world: mujoco.MjsBody) -> None:
    spec.add_mesh(
        name="hex_prism", uservert=hex_prism_vertices(HEX_CIRCUMRADIUS, SHAPES["hex_prism"].half_height)
    )
    for i, (name, shape) in enumerate(SHAPES.items()):
        body = world.add_body(name=f"obj_{name}", pos=[PARK_XY[0], PARK_XY[1] + 0.1 * i, shape.half_height])
        body.add_freejoint(name=f"obj_{name}")
        geom = body.add_geom(
            name=f"obj_{name}",
            type=shape.geom_type,
            mass=OBJECT_MASS,
            friction=list(OBJECT_FRICTION),
            rgba=[1, 0, 0, 1],
            condim=4,
        )
        if shape.geom_type == mujoco.mjtGeom.mjGEOM_MESH:
            geom.meshname = "hex_prism"
        else:
            geom.size = list(shape.size)


@dataclass
class SceneIds:
    """Ids looked up by name once after compiling (no magic integers elsewhere)."""

    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    arm_range: np.ndarray  # (7, 2) joint limits, rad
    arm_actuators: np.ndarray
    gripper_actuator: int
    gripper_qpos: int
    pinch_site: int
    pad_geoms: frozenset[int]
    table_geom: int
    cameras: dict[str, int]
    shape_body: dict[str, int]
    shape_geom: dict[str, int]
    shape_qpos: dict[str, int]
    shape_dof: dict[str, int]
    robot_geoms: frozenset[int]

    @classmethod
    def lookup(cls, model: mujoco.MjModel) -> SceneIds:
        robot_bodies = {i for i in range(model.nbody) if model.body(i).name.startswith(PANDA_PREFIX)}
        return cls(
            arm_qpos=np.array([model.joint(j).qposadr[0] for j in ARM_JOINTS]),
            arm_dof=np.array([model.joint(j).dofadr[0] for j in ARM_JOINTS]),
            arm_range=model.jnt_range[[model.joint(j).id for j in ARM_JOINTS]].copy(),
            arm_actuators=np.array([model.actuator(a).id for a in ARM_ACTUATORS]),
            gripper_actuator=model.actuator(GRIPPER_ACTUATOR).id,
            gripper_qpos=int(model.joint(GRIPPER_JOINT).qposadr[0]),
            pinch_site=model.site(PINCH_SITE).id,
            pad_geoms=frozenset(model.geom(g).id for g in PAD_GEOMS),
            table_geom=model.geom("table").id,
            cameras={
                name: model.camera(name if name != "wrist" else f"{PANDA_PREFIX}wrist").id
                for name in ALL_CAMERAS
            },
            shape_body={s: model.body(f"obj_{s}").id for s in SHAPES},
            shape_geom={s: model.geom(f"obj_{s}").id for s in SHAPES},
            shape_qpos={s: int(model.joint(f"obj_{s}").qposadr[0]) for s in SHAPES},
            shape_dof={s: int(model.joint(f"obj_{s}").dofadr[0]) for s in SHAPES},
            robot_geoms=frozenset(i for i in range(model.ngeom) if model.geom_bodyid[i] in robot_bodies),
        )


class Scene:
    """A compiled scene plus in-place setters for everything an instance varies."""

    def __init__(
        self,
        quality: RenderQuality = "fast",
        target: SpecAddition | None = None,
        extras: Sequence[SpecAddition] = (),
    ) -> None:
        if quality not in ("fast", "high"):
            raise ValueError(f"unknown render quality {quality!r}; allowed: 'fast', 'high'")
        self.quality = quality
        self.spec = build_spec(quality, target, extras)
        self.model = self.spec.compile()
        self.data = mujoco.MjData(self.model)
        self.ids = SceneIds.lookup(self.model)
        self.active_shape = next(iter(SHAPES))

    def set_camera(self, pose: CameraPose) -> None:
        cam = self.ids.cameras[pose.name]
        self.model.cam_pos[cam] = pose.pos
        self.model.cam_quat[cam] = pose.quat
        self.model.cam_fovy[cam] = pose.fovy

    def model_camera_pose(self, name: str) -> CameraPose:
        """The pose a scene camera is compiled with now (its model pos/quat/fovy; world frame)."""
        cam = self.ids.cameras[name]
        return CameraPose(
            name,
            tuple(self.model.cam_pos[cam].tolist()),
            tuple(self.model.cam_quat[cam].tolist()),
            float(self.model.cam_fovy[cam]),
        )

    def camera_pose(self, name: str) -> CameraPose:
        """Current world pose of any camera (including the wrist camera, after mj_forward)."""
        cam = self.ids.cameras[name]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, self.data.cam_xmat[cam])
        if quat[0] < 0:
            quat = -quat
        return CameraPose(
            name,
            tuple(self.data.cam_xpos[cam].tolist()),
            tuple(quat.tolist()),
            float(self.model.cam_fovy[cam]),
        )

    @property
    def active_geom(self) -> int:
        """Geom id of the object on the table (what the `color` factor paints)."""
        return self.ids.shape_geom[self.active_shape]

    def place_object(self, shape: str, xy: np.ndarray, yaw: float) -> None:
        """Put `shape` on the table at `xy` with heading `yaw`; park every other shape."""
        self.active_shape = shape
        for i, (name, spec) in enumerate(SHAPES.items()):
            adr = self.ids.shape_qpos[name]
            if name == shape:
                pos = [xy[0], xy[1], spec.half_height]
                quat = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
            else:
                pos = [PARK_XY[0], PARK_XY[1] + 0.1 * i, spec.half_height]
                quat = [1.0, 0.0, 0.0, 0.0]
            self.data.qpos[adr : adr + 3] = pos
            self.data.qpos[adr + 3 : adr + 7] = quat
            dof = self.ids.shape_dof[name]
            self.data.qvel[dof : dof + 6] = 0.0

    def reset_robot(self, qpos: np.ndarray = HOME_QPOS) -> None:
        self.data.qpos[self.ids.arm_qpos] = qpos
        self.data.qvel[self.ids.arm_dof] = 0.0
        self.data.ctrl[self.ids.arm_actuators] = qpos
        self.data.ctrl[self.ids.gripper_actuator] = 0.0
