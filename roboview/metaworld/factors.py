"""Visual factors in Meta-World's scenes, applied in place to the compiled model after every reset.

The scene keeps one compiled model and one render context; before every reset the pristine visual arrays (and the
context's material-texture table, which MuJoCo copies when the context is made) are put back, then the instance's
appliers run. Every baseline is Meta-World's scene unchanged (as LeRobot's `MetaworldEnv` renders it).

- `ObjectColor`: the task's object (`OBJECTS`, the scene's `object_body`) re-skinned a solid color (its geoms' material detached: Meta-World's
  wood and metal textures would otherwise tint it).
- `OrbitalPose`, `CameraEuler`, `PullBack`: `corner2`, the camera a policy watches (the math is shared with
  LIBERO's: `roboview.variation.model_edits`). corner2 renders upside down and LeRobot flips it; the rotations here
  act on the flipped (observed) frame, so +6° of yaw turns the observed view as it does in the other worlds.
- `Lighting`: every light's diffuse level and, away from `top`, its direction.
- `TableTexture`: the table top's texture (`T_table`) rewritten with RoboView's texture of that name.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from roboview.variation.model_edits import (  # noqa: F401  (Lighting: Meta-World's lighting applier)
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

VISIBLE_GROUPS = (0, 1, 2)  # what gymnasium's renderer draws by default (Meta-World's collision geoms: 3, 4)
# The point every orbital pose looks at: the middle of the region Meta-World's objects and goals start in.
WORKSPACE_CENTER = np.array([0.0, 0.65, 0.05])
TABLE_TEXTURE = "T_table"
_FLIP = np.diag([-1.0, -1.0, 1.0])  # corner2's raw frame ↔ the observed (flipped) frame
_MODEL_FIELDS = ("geom_rgba", "geom_matid", "mat_rgba", "cam_pos", "cam_quat") + tuple(
    f"light_{f}" for f in ("diffuse", "dir", "pos")
)


def snapshot_visuals(scene) -> dict[str, np.ndarray]:
    model = scene.model
    snap = {name: getattr(model, name).copy() for name in _MODEL_FIELDS}
    snap["tex_data"] = model.tex_data.copy()
    return snap


def restore_visuals(scene, snap: dict[str, np.ndarray]) -> None:
    model = scene.model
    for name in _MODEL_FIELDS:
        getattr(model, name)[:] = snap[name]
    tex = table_texture(model)
    sl = tex_slice(model, tex)
    if not np.array_equal(model.tex_data[sl], snap["tex_data"][sl]):
        model.tex_data[sl] = snap["tex_data"][sl]
        _upload(scene, tex)


def object_geoms(model: mujoco.MjModel, body: str) -> list[int]:
    """The visible geoms of `body` and every body below it."""
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    if root < 0:
        raise ValueError(f"no body named {body!r} in the Meta-World model")
    return subtree_geoms(model, root, VISIBLE_GROUPS)


def table_texture(model: mujoco.MjModel) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXTURE, TABLE_TEXTURE)


def _upload(scene, tex: int) -> None:
    scene.make_current()
    mujoco.mjr_uploadTexture(scene.model, scene.render_context, tex)


def _set_camera(scene, pos: np.ndarray, observed_rot: np.ndarray) -> None:
    """corner2 at `pos`, its observed (flipped) frame `observed_rot` (columns right, up, backward)."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(observed_rot @ _FLIP, float).reshape(9))
    scene.model.cam_pos[scene.camera_id], scene.model.cam_quat[scene.camera_id] = pos, quat


def _camera(scene) -> tuple[np.ndarray, np.ndarray]:
    """corner2's position and observed (flipped) frame."""
    cam = scene.camera_id
    return scene.model.cam_pos[cam].copy(), rotation(scene.model.cam_quat[cam]) @ _FLIP


@dataclass(frozen=True)
class ObjectColor:
    """The geoms of `body` (None: the scene's task object, `MetaWorldScene.object_body`) colored `rgb` (0–1), their
    material detached."""

    rgb: tuple[float, float, float]
    body: str | None = None

    def apply(self, scene) -> None:
        for geom in object_geoms(scene.model, self.body or scene.object_body):
            scene.model.geom_rgba[geom, :3] = self.rgb
            scene.model.geom_matid[geom] = -1


@dataclass(frozen=True)
class OrbitalPose:
    """corner2 on ring `ring`, azimuth offset `k`, looking at WORKSPACE_CENTER."""

    ring: int
    k: int

    def apply(self, scene) -> None:
        pos, _ = _camera(scene)
        eye = orbit_eye(WORKSPACE_CENTER, pos, self.ring, self.k)
        _set_camera(scene, eye, look_at(eye, WORKSPACE_CENTER))


@dataclass(frozen=True)
class CameraEuler:
    """corner2 turned `yaw_deg` about its own (observed) up axis, then `pitch_deg` about its right axis."""

    yaw_deg: float
    pitch_deg: float

    def apply(self, scene) -> None:
        pos, rot = _camera(scene)
        _set_camera(scene, pos, turned(rot, self.yaw_deg, self.pitch_deg))


@dataclass(frozen=True)
class PullBack:
    """corner2 moved back 0.05·k m along its optical axis."""

    k: int

    def apply(self, scene) -> None:
        pos, rot = _camera(scene)
        _set_camera(scene, pulled_back(pos, rot, self.k), rot)


@dataclass(frozen=True)
class TableTexture:
    """The table top's texture replaced by RoboView's `table_texture` value `pattern`."""

    pattern: str

    def __post_init__(self) -> None:
        texture_pixels(self.pattern, 1, 1, 1)  # validates the name

    def apply(self, scene) -> None:
        model = scene.model
        tex = table_texture(model)
        h, w, c = model.tex_height[tex], model.tex_width[tex], model.tex_nchannel[tex]
        model.tex_data[tex_slice(model, tex)] = texture_pixels(self.pattern, h, w, c).reshape(-1)
        _upload(scene, tex)
