"""Camera geometry: poses, look-at, quaternions, and the scene's unperturbed cameras.

Every pose is world-frame, MuJoCo convention: the camera looks along its local −z with +y up,
`quat` is [w, x, y, z]. The camera *factors* (orbital pose, Euler turn, pull-back) live with the
other factors in `roboview.variation.factors.camera`; they move only ``front`` and
``left_top`` (PERTURBED_CAMERAS), never ``right_top`` or ``wrist``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Point every orbital camera (and the fixed scene cameras) looks at: between the object
# positions and the receiver box, slightly above the table.
WORKSPACE_CENTER = np.array([0.48, 0.02, 0.03])

# Side of the square camera images the renderer makes (pixels): the one bound every image size is
# checked against. A consumer that needs larger images raises the minimum for a reason it states.
IMAGE_SIZE_MIN = 16
IMAGE_SIZE_MAX = 640


def check_image_size(
    size: int, name: str = "image_size", minimum: int = IMAGE_SIZE_MIN, why: str = ""
) -> None:
    """ValueError naming `name`={size} and the allowed range unless minimum ≤ size ≤ IMAGE_SIZE_MAX; `why`
    (appended in parentheses) says why a caller's minimum lies above IMAGE_SIZE_MIN."""
    if not minimum <= size <= IMAGE_SIZE_MAX:
        because = f" ({why})" if why else ""
        raise ValueError(f"{name}={size} out of range; allowed {minimum}..{IMAGE_SIZE_MAX}{because}")


# Cameras that a camera factor moves together.
PERTURBED_CAMERAS = ("front", "left_top")
ALL_CAMERAS = ("front", "left_top", "right_top", "wrist")

DEFAULT_FOVY_DEG = 45.0


@dataclass(frozen=True)
class CameraPose:
    """A world-frame camera pose: position (m), quaternion [w, x, y, z], vertical field of view (deg)."""

    name: str
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    fovy: float = DEFAULT_FOVY_DEG

    @property
    def rotation(self) -> np.ndarray:
        """3×3 camera-to-world rotation; columns are the camera's x (right), y (up), z (backward) axes."""
        return quat_to_mat(np.asarray(self.quat))

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit vector the camera looks along (its −z axis) in world coordinates."""
        return -self.rotation[:, 2]

    def to_record(self) -> dict:
        return {
            "name": self.name,
            "pos": [float(v) for v in self.pos],
            "quat": [float(v) for v in self.quat],
            "fovy": float(self.fovy),
        }


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = quat / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def mat_to_quat(mat: np.ndarray) -> np.ndarray:
    """Rotation matrix → unit quaternion [w, x, y, z] with w ≥ 0 (canonical sign, so records are stable)."""
    m = np.asarray(mat, dtype=float)
    trace = np.trace(m)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = np.array([(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s])
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = np.array([(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = np.array([(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def camera_pose_of(model, data, cam: int, name: str) -> CameraPose:
    """Camera `cam` of a compiled model as `name`'s CameraPose now (frames refreshed from the live state): how the
    worlds whose scenes RoboView does not build (LIBERO's, Meta-World's) record and certify their cameras."""
    import mujoco

    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    quat = mat_to_quat(data.cam_xmat[cam].reshape(3, 3))
    return CameraPose(
        name, tuple(map(float, data.cam_xpos[cam])), tuple(map(float, quat)), float(model.cam_fovy[cam])
    )


def look_at(
    name: str, eye: np.ndarray, target: np.ndarray = WORKSPACE_CENTER, fovy: float = DEFAULT_FOVY_DEG
) -> CameraPose:
    """Pose at `eye` looking at `target` with world +z projected as image up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    backward = eye - target
    backward /= np.linalg.norm(backward)
    right = np.cross([0.0, 0.0, 1.0], backward)
    right /= np.linalg.norm(right)
    up = np.cross(backward, right)
    quat = mat_to_quat(np.column_stack([right, up, backward]))
    return CameraPose(name, tuple(eye.tolist()), tuple(quat.tolist()), fovy)


# The unperturbed scene cameras (the camera factors' baseline).
BASE_CAMERAS: dict[str, CameraPose] = {
    "front": look_at("front", np.array([1.18, -0.02, 0.62]), np.array([0.48, -0.02, 0.03]), fovy=50.0),
    "left_top": look_at("left_top", np.array([0.60, 0.64, 0.64])),
    "right_top": look_at("right_top", np.array([0.60, -0.64, 0.64])),
}
