"""Camera geometry: the fixed scene cameras and the three camera factors of the paper.

Every pose is world-frame, MuJoCo convention: the camera looks along its local −z with +y up,
`quat` is [w, x, y, z]. Factor values are applied to the *base* pose of a scene camera:

- ``camera_pose`` (orbital): replaces the pose by one of 21 look-at poses on three concentric
  rings above the workspace, in front of the arm (appendix "Camera Settings").
- ``camera_euler`` (yaw, pitch): rotates the camera about its own +y (yaw) and +x (pitch) axes.
- ``dist_scale`` k: moves the camera backward along its optical axis by 0.05·k m.

Only ``front`` and ``left_top`` are perturbed (DESIGN.md); ``right_top`` and ``wrist`` never are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview_data.variation.factors import parse_dist_scale, parse_euler

# Point every orbital camera (and the fixed scene cameras) looks at: between the object
# positions and the receiver box, slightly above the table.
WORKSPACE_CENTER = np.array([0.48, 0.02, 0.03])

# Cameras that a camera factor moves together, and those it never touches.
PERTURBED_CAMERAS = ("front", "left_top")
SCENE_CAMERAS = ("front", "left_top", "right_top")
ALL_CAMERAS = ("front", "left_top", "right_top", "wrist")

# Orbital rings: horizontal radius (m) around WORKSPACE_CENTER and height above the table (m);
# seven azimuths per ring, spread over the half-space in front of the arm (+x).
ORBIT_RINGS = ((0.30, 0.80), (0.45, 0.72), (0.60, 0.62))
ORBIT_AZIMUTHS_DEG = tuple(np.linspace(-72.0, 72.0, 7))

DIST_STEP_M = 0.05
DEFAULT_FOVY_DEG = 45.0
# Orbital cameras see the whole workspace (objects and box) from closer in: a wider lens.
ORBIT_FOVY_DEG = 50.0


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
        return {"name": self.name, "pos": [float(v) for v in self.pos],
                "quat": [float(v) for v in self.quat], "fovy": float(self.fovy)}


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = quat / np.linalg.norm(quat)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


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


def look_at(name: str, eye: np.ndarray, target: np.ndarray = WORKSPACE_CENTER,
            fovy: float = DEFAULT_FOVY_DEG) -> CameraPose:
    """Pose at `eye` looking at `target` with world +z projected as image up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    backward = eye - target
    backward /= np.linalg.norm(backward)
    right = np.cross([0.0, 0.0, 1.0], backward)
    right /= np.linalg.norm(right)
    up = np.cross(backward, right)
    quat = mat_to_quat(np.column_stack([right, up, backward]))
    return CameraPose(name, tuple(eye.tolist()), tuple(quat.tolist()), fovy)


# The unperturbed ("original") scene cameras.
BASE_CAMERAS: dict[str, CameraPose] = {
    "front": look_at("front", np.array([1.18, -0.02, 0.62]), np.array([0.48, -0.02, 0.03]), fovy=50.0),
    "left_top": look_at("left_top", np.array([0.60, 0.64, 0.64])),
    "right_top": look_at("right_top", np.array([0.60, -0.64, 0.64])),
}


def orbital_pose(name: str, value: str) -> CameraPose:
    """Pose of camera `name` at orbital value "orbit_r{ring}_{k}": on ring `ring`, azimuth index k."""
    ring, k = (int(part[1:]) if part.startswith("r") else int(part) for part in value.split("_")[1:])
    radius, height = ORBIT_RINGS[ring]
    azimuth = np.deg2rad(ORBIT_AZIMUTHS_DEG[k])
    eye = WORKSPACE_CENTER + np.array([radius * np.cos(azimuth), radius * np.sin(azimuth), height])
    return look_at(name, eye, fovy=ORBIT_FOVY_DEG)


def apply_euler(pose: CameraPose, yaw_deg: float, pitch_deg: float) -> CameraPose:
    """Rotate about the camera's own up axis (yaw), then its right axis (pitch)."""
    yaw, pitch = np.deg2rad(yaw_deg), np.deg2rad(pitch_deg)
    r_yaw = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    r_pitch = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    rot = pose.rotation @ r_yaw @ r_pitch
    return CameraPose(pose.name, pose.pos, tuple(mat_to_quat(rot).tolist()), pose.fovy)


def apply_distance(pose: CameraPose, k: int) -> CameraPose:
    """Move the camera backward along its optical axis by DIST_STEP_M·k."""
    pos = np.asarray(pose.pos) - DIST_STEP_M * k * pose.optical_axis
    return CameraPose(pose.name, tuple(pos.tolist()), pose.quat, pose.fovy)


def scene_camera_poses(camera_pose: str, camera_euler: str, dist_scale: str) -> dict[str, CameraPose]:
    """World poses of the three scene cameras for one instance's camera factor values.

    The factors compose in a fixed order (orbital placement, then Euler, then distance), although
    each benchmark instance varies at most one of them.
    """
    yaw, pitch = parse_euler(camera_euler)
    k = parse_dist_scale(dist_scale)
    poses = {}
    for name, base in BASE_CAMERAS.items():
        pose = base
        if name in PERTURBED_CAMERAS:
            if camera_pose != "original":
                pose = orbital_pose(name, camera_pose)
            if (yaw, pitch) != (0, 0):
                pose = apply_euler(pose, yaw, pitch)
            if k:
                pose = apply_distance(pose, k)
        poses[name] = pose
    return poses
