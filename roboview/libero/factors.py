"""Visual factors for LIBERO scenes, applied in place to the compiled MuJoCo model after every reset.

A LIBERO hard reset compiles a new `MjModel` and render context, so an applier is a small frozen dataclass with
`apply(world)` that `LiberoWorld` calls after each reset (before the init state is loaded: nothing here touches
physics, and the init state's `forward()` then refreshes camera and light frames). Appliers set absolute values
derived from the pristine model, so applying twice is the same as once.

The factors:

- `ObjectColor(rgb, mode)`: the task's target object (`target_object`: LIBERO's `obj_of_interest[0]`, the object the
  instruction manipulates — "alphabet_soup_1", "akita_black_bowl_1", "wooden_cabinet_1"…; its visual geoms, group 1).
  Every object of the four suites is one textured mesh whose material carries a 2048² texture. `tint` sets
  `mat_rgba`/`geom_rgba` to `rgb`, which MuJoCo multiplies onto the texture (shading and print survive; a dark object
  barely changes); `skin` drops the texture (`mat_texid = -1`, also in the render context's cached copy) and paints
  the material `rgb`: a solid re-skin.
- Camera factors move only `agentview`, never the wrist camera: `OrbitalPose(ring, k)` puts it on one of 3 × 7
  look-at poses around `workspace_center` (the centroid of the task's movable objects in the init state) at its own
  distance from that center; `CameraEuler(yaw, pitch)` turns it about its own up/right axes; `PullBack(k)` moves it
  back 0.05 m·k along its optical axis. They compose in that order.
- `Lighting(scale, direction)`: every light's diffuse scaled; optionally every light pointed along `direction`.
- `TableTexture(pattern)`: the support surface under `workspace_center` (a downward ray, static geoms only: the table
  top, or the floor in floor scenes) gets a procedural texture written into `tex_data` and uploaded with
  `mjr_uploadTexture` on the live render context (the first static textured geom below: the hand and the objects are
  looked past).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from roboview.variation.model_edits import (  # noqa: F401  (Lighting: LIBERO's lighting applier)
    ORBIT_AZIMUTHS_DEG,
    ORBIT_ELEVATIONS_DEG,
    Lighting,
    look_at,
    orbit_eye,
    pulled_back,
    rotation,
    subtree_geoms,
    tex_slice,
    texture_pixels,
    turned,
)

AGENTVIEW = "agentview"
WRIST = "robot0_eye_in_hand"
VISUAL_GROUP = 1  # robosuite renders geom group 1 (visual meshes) only
_MODEL_FIELDS = ("geom_rgba", "mat_rgba", "mat_texid", "cam_pos", "cam_quat", "cam_fovy") + tuple(
    f"light_{f}" for f in ("diffuse", "ambient", "specular", "dir", "pos")
)


# ---- snapshot / restore (soft resets keep the edited model) --------------------------------------------------
def snapshot_visuals(world) -> dict[str, np.ndarray]:
    """Copies of every model array an applier here may edit, plus the render context's material textures."""
    model = world.model
    snap = {name: getattr(model, name).copy() for name in _MODEL_FIELDS}
    snap["con_mat_texid"] = np.array(world.render_context.con.mat_texid)
    snap["tex_data"] = model.tex_data.copy()
    return snap


def restore_visuals(world, snap: dict[str, np.ndarray]) -> None:
    """Put the pristine visual arrays back (soft reset), re-uploading textures whose pixels changed."""
    model, con = world.model, world.render_context.con
    for name in _MODEL_FIELDS:
        getattr(model, name)[:] = snap[name]
    con.mat_texid[:] = snap["con_mat_texid"]
    for tex in range(model.ntex):
        sl = tex_slice(model, tex)
        if not np.array_equal(model.tex_data[sl], snap["tex_data"][sl]):
            model.tex_data[sl] = snap["tex_data"][sl]
            _upload(world, tex)


# ---- scene queries ------------------------------------------------------------------------------------------
def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    idx = mujoco.mj_name2id(model, kind, name)
    if idx < 0:
        raise ValueError(f"no {kind.name.removeprefix('mjOBJ_').lower()} named {name!r} in the LIBERO model")
    return idx


def owner_object(world, name: str) -> str | None:
    """The LIBERO object or fixture `name` names: itself, or, for a region of one (`wooden_cabinet_1_middle_region`,
    `basket_1_contain_region`: named `<object>_<region>` as LIBERO names regions), the object it belongs to; None for
    a region of no object (a table's: `main_table_stove_front_region`)."""
    objects = {**world.inner.fixtures_dict, **world.inner.objects_dict}
    owners = [o for o in objects if name.startswith(o + "_")]
    return name if name in objects else max(owners, key=len) if owners else None


def target_object(world) -> str:
    """The task's target object: LIBERO's `obj_of_interest[0]` (the object the instruction acts on). Where that is a
    region of an object (libero_goal's "open the middle drawer of the cabinet": `wooden_cabinet_1_middle_region`),
    the object the region belongs to (`owner_object`)."""
    name = world.inner.obj_of_interest[0]
    return owner_object(world, name) or name


def goal_places(world) -> list[str]:
    """Where the task's goal puts things, or what it changes, besides the target object: the last term of each
    predicate of LIBERO's parsed goal (`parsed_problem["goal_state"]`) — `(In soup basket_1_contain_region)`'s
    region, `(On bowl plate_1)`'s plate, `(Turnon flat_stove_1)`'s stove — as the object it belongs to (`basket_1`,
    `plate_1`, `flat_stove_1`), or, for a region of no object (`(On plate_1 main_table_stove_front_region)`), the
    region: a site of LIBERO's model. In the goal's order, each once; the target object left out."""
    target, out = target_object(world), []
    for predicate in world.inner.parsed_problem["goal_state"]:
        place = owner_object(world, predicate[-1]) or predicate[-1]
        if place != target and place not in out:
            out.append(place)
    return out


def object_geoms(world, name: str) -> list[int]:
    """Visual geoms of LIBERO object `name` (its root body and every body below it)."""
    objects = {**world.inner.fixtures_dict, **world.inner.objects_dict}
    if name not in objects:
        raise ValueError(f"unknown object {name!r}; allowed: {', '.join(sorted(objects))}")
    root = _id(world.model, mujoco.mjtObj.mjOBJ_BODY, objects[name].root_body)
    return subtree_geoms(world.model, root, (VISUAL_GROUP,))


def workspace_center(world) -> np.ndarray:
    """Centroid of the task's movable objects in the world's init state (kinematics on a scratch MjData)."""
    model, state = world.model, np.asarray(world._init_state)
    scratch = mujoco.MjData(model)
    scratch.time = state[0]
    scratch.qpos[:] = state[1 : 1 + model.nq]
    mujoco.mj_kinematics(model, scratch)
    roots = [_id(model, mujoco.mjtObj.mjOBJ_BODY, obj.root_body) for obj in world.inner.objects_dict.values()]
    return scratch.xpos[roots].mean(axis=0)


def camera_pose(world, name: str = AGENTVIEW) -> tuple[np.ndarray, np.ndarray]:
    """(pos, quat wxyz) of a world-fixed camera in the model."""
    cam = _id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    return world.model.cam_pos[cam].copy(), world.model.cam_quat[cam].copy()


def _set_agentview(world, pos: np.ndarray, rot: np.ndarray) -> None:
    model = world.model
    cam = _id(model, mujoco.mjtObj.mjOBJ_CAMERA, AGENTVIEW)
    if model.cam_bodyid[cam] != 0:
        raise RuntimeError("agentview is expected to hang from the world body")
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(rot, float).reshape(9))
    model.cam_pos[cam], model.cam_quat[cam] = pos, quat


def _upload(world, tex: int) -> None:
    ctx = world.render_context
    ctx.gl_ctx.make_current()
    mujoco.mjr_uploadTexture(world.model, ctx.con, tex)  # robosuite's upload_texture passes its model wrapper


# ---- appliers -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ObjectColor:
    """Target object (or `object_name`) colored `rgb` (0–1): `mode` "tint" (× texture) or "skin" (solid)."""

    rgb: tuple[float, float, float]
    mode: str = "tint"
    object_name: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in ("tint", "skin"):
            raise ValueError(f"mode {self.mode!r} invalid; allowed: tint, skin")

    @classmethod
    def skin(cls, rgb: tuple[float, float, float]) -> ObjectColor:
        """The target object re-skinned `rgb`: LIBERO's `color` factor (a tint barely shows on its dark textures)."""
        return cls(rgb, mode="skin")

    def apply(self, world) -> None:
        model, con = world.model, world.render_context.con
        n_roles = model.mat_texid.shape[1]
        for geom in object_geoms(world, self.object_name or target_object(world)):
            model.geom_rgba[geom, :3] = self.rgb
            mat = model.geom_matid[geom]
            if mat < 0:
                continue
            model.mat_rgba[mat, :3] = self.rgb
            if self.mode == "skin":
                model.mat_texid[mat] = -1
                con.mat_texid[mat * n_roles : (mat + 1) * n_roles] = -1  # the context caches it at creation


@dataclass(frozen=True)
class OrbitalPose:
    """agentview on ring `ring` (elevation ORBIT_ELEVATIONS_DEG[ring]) at azimuth offset ORBIT_AZIMUTHS_DEG[k]."""

    ring: int
    k: int

    def __post_init__(self) -> None:
        if not (0 <= self.ring < len(ORBIT_ELEVATIONS_DEG) and 0 <= self.k < len(ORBIT_AZIMUTHS_DEG)):
            raise ValueError(
                f"orbital pose ({self.ring}, {self.k}) out of range; allowed: ring 0..{len(ORBIT_ELEVATIONS_DEG) - 1},"
                f" k 0..{len(ORBIT_AZIMUTHS_DEG) - 1}"
            )

    def apply(self, world) -> None:
        center = workspace_center(world)
        pos, _ = camera_pose(world)
        eye = orbit_eye(center, pos, self.ring, self.k)
        _set_agentview(world, eye, look_at(eye, center))


@dataclass(frozen=True)
class CameraEuler:
    """agentview turned `yaw_deg` about its own up axis, then `pitch_deg` about its own right axis."""

    yaw_deg: float
    pitch_deg: float

    def apply(self, world) -> None:
        pos, quat = camera_pose(world)
        _set_agentview(world, pos, turned(rotation(quat), self.yaw_deg, self.pitch_deg))


@dataclass(frozen=True)
class PullBack:
    """agentview moved back DIST_STEP_M·k along its optical axis."""

    k: int

    def apply(self, world) -> None:
        pos, quat = camera_pose(world)
        rot = rotation(quat)
        _set_agentview(world, pulled_back(pos, rot, self.k), rot)


def support_texture(world) -> int:
    """Texture of the support surface below workspace_center (the table top, or the floor): the first static,
    textured visual geom a downward ray meets. The hand hovering over the objects (libero_10's living-room tasks) and
    the objects themselves are dynamic geoms: the ray looks past them."""
    model, data = world.model, world.data
    start, down = workspace_center(world) + [0, 0, 0.3], np.array([0.0, 0.0, -1.0])
    groups = np.zeros(6, np.uint8)
    groups[VISUAL_GROUP] = 1
    geom = np.zeros(1, np.int32)
    for _ in range(64):  # at most the geoms stacked under the center
        dist = mujoco.mj_ray(model, data, start, down, groups, 1, -1, geom)
        if geom[0] < 0:
            break
        mat = model.geom_matid[geom[0]]
        tex = model.mat_texid[mat, mujoco.mjtTextureRole.mjTEXROLE_RGB] if mat >= 0 else -1
        if model.body_weldid[model.geom_bodyid[geom[0]]] == 0 and tex >= 0:
            return int(tex)
        start = start + down * (dist + 1e-4)
    raise RuntimeError("no textured support surface found below the workspace center")


@dataclass(frozen=True)
class TableTexture:
    """The support surface's texture replaced by `pattern` (one of TEXTURE_PATTERNS)."""

    pattern: str
    # Restoring the texture in place leaves edge pixels of later renders off by a few levels (the render
    # context's texture state): the world compiles a new model after an episode with this factor.
    in_place = False

    def __post_init__(self) -> None:
        texture_pixels(self.pattern, 1, 1, 1)  # validates the name

    def apply(self, world) -> None:
        model = world.model
        tex = support_texture(world)
        h, w, c = model.tex_height[tex], model.tex_width[tex], model.tex_nchannel[tex]
        model.tex_data[tex_slice(model, tex)] = texture_pixels(self.pattern, h, w, c).reshape(-1)
        _upload(world, tex)
