"""The paper's three camera factors: `camera_pose` (orbital), `camera_euler`, `dist_scale`.

Every pose is world-frame, MuJoCo convention (roboview.sim.cameras). Only the `front` and
`left_top` cameras are perturbed; `right_top` and `wrist` never are. The three appliers compose in
registration order — orbital placement (or the unperturbed pose), then the Euler turn, then the
pull-back — although each benchmark instance varies at most one of them.

- ``camera_pose``: one of 21 look-at poses on three concentric rings above the workspace, in
  front of the arm (appendix "Camera Settings"), or the baseline ``original`` cameras.
- ``camera_euler`` "yaw,pitch": rotates the camera about its own +y (yaw) and +x (pitch) axes.
- ``dist_scale`` k: moves the camera backward along its optical axis by DIST_STEP_M·k.
"""

from __future__ import annotations

import numpy as np

from roboview.sim.cameras import (
    BASE_CAMERAS,
    PERTURBED_CAMERAS,
    WORKSPACE_CENTER,
    CameraPose,
    look_at,
    mat_to_quat,
)
from roboview.variation.factors.base import Factor, register_factor

# Orbital rings: horizontal radius (m) around WORKSPACE_CENTER and height above the table (m);
# seven azimuths per ring, spread over the half-space in front of the arm (+x).
ORBIT_RINGS = ((0.30, 0.80), (0.45, 0.72), (0.60, 0.62))
ORBIT_AZIMUTHS_DEG = tuple(np.linspace(-72.0, 72.0, 7))
N_ORBIT_RINGS = len(ORBIT_RINGS)
N_ORBIT_POSES_PER_RING = len(ORBIT_AZIMUTHS_DEG)
# Orbital cameras see the whole workspace (objects and box) from closer in: a wider lens.
ORBIT_FOVY_DEG = 50.0
CAMERA_POSE_BASELINE = "original"
EULER_STEPS_DEG = (-6, 0, 6)
DIST_STEP_M = 0.05
N_DIST_SCALE_LEVELS = 9


def parse_camera_pose(value: str) -> tuple[int, int] | None:
    """Parse 'orbit_r{ring}_{k}' into (ring, k); None means the unperturbed (baseline) cameras."""
    CAMERA_POSE.validate(value)
    if value == CAMERA_POSE_BASELINE:
        return None
    ring, k = value.removeprefix("orbit_r").split("_")
    return int(ring), int(k)


def parse_euler(value: str) -> tuple[int, int]:
    """Parse a camera_euler value 'yaw,pitch' into integer degrees (yaw_deg, pitch_deg)."""
    CAMERA_EULER.validate(value)
    yaw, pitch = value.split(",")
    return int(yaw), int(pitch)


def parse_dist_scale(value: str) -> int:
    """Parse a dist_scale value into k; the camera moves back DIST_STEP_M * k metres."""
    DIST_SCALE.validate(value)
    return int(value)


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
    """World poses of the three scene cameras for one instance's camera factor values (no scene needed;
    the appliers below produce the same poses in a compiled model)."""
    yaw, pitch = parse_euler(camera_euler)
    k = parse_dist_scale(dist_scale)
    poses = {}
    for name, base in BASE_CAMERAS.items():
        pose = base
        if name in PERTURBED_CAMERAS:
            if camera_pose != CAMERA_POSE_BASELINE:
                pose = orbital_pose(name, camera_pose)
            if (yaw, pitch) != (0, 0):
                pose = apply_euler(pose, yaw, pitch)
            if k:
                pose = apply_distance(pose, k)
        poses[name] = pose
    return poses


class _CameraApplier:
    """Bound to the perturbed cameras' rows of the model's cam_pos / cam_quat / cam_fovy."""

    def __init__(self, scene) -> None:
        self.scene = scene

    def _current(self, name: str) -> CameraPose:
        return self.scene.model_camera_pose(name)


class OrbitalPose(_CameraApplier):
    def apply(self, value: str, rng: np.random.Generator) -> None:
        for name in PERTURBED_CAMERAS:
            base = BASE_CAMERAS[name]
            self.scene.set_camera(base if value == CAMERA_POSE_BASELINE else orbital_pose(name, value))


class EulerTurn(_CameraApplier):
    def apply(self, value: str, rng: np.random.Generator) -> None:
        yaw, pitch = parse_euler(value)
        if (yaw, pitch) != (0, 0):
            for name in PERTURBED_CAMERAS:
                self.scene.set_camera(apply_euler(self._current(name), yaw, pitch))


class PullBack(_CameraApplier):
    def apply(self, value: str, rng: np.random.Generator) -> None:
        k = parse_dist_scale(value)
        if k:
            for name in PERTURBED_CAMERAS:
                self.scene.set_camera(apply_distance(self._current(name), k))


# The cameras these factors move: what the isolation certificate lets differ across their values (RoboView's
# `front` and `left_top`; in LIBERO's scenes, roboview.libero.task, `agentview`).
MOVED = (*(f"camera:{name}" for name in PERTURBED_CAMERAS), "camera:agentview")

CAMERA_POSE = register_factor(
    Factor(
        name="camera_pose",
        kind="visual",
        values=tuple(
            f"orbit_r{ring}_{k}" for ring in range(N_ORBIT_RINGS) for k in range(N_ORBIT_POSES_PER_RING)
        ),
        baseline=CAMERA_POSE_BASELINE,
        doc=(
            "Pose of the front and left_top cameras: one of 21 orbital poses (ring r, index k) "
            f"looking at the workspace center, or {CAMERA_POSE_BASELINE!r} for the unperturbed cameras."
        ),
        title="Camera Pose",
        bind=OrbitalPose,
        always_in_id=True,
        alters=MOVED,
    )
)
CAMERA_EULER = register_factor(
    Factor(
        name="camera_euler",
        kind="visual",
        values=tuple(f"{yaw},{pitch}" for yaw in EULER_STEPS_DEG for pitch in EULER_STEPS_DEG),
        baseline="0,0",
        doc="'yaw,pitch' in degrees: rotation of front and left_top about their own axes.",
        title="Camera Euler",
        bind=EulerTurn,
        always_in_id=True,
        alters=MOVED,
    )
)
DIST_SCALE = register_factor(
    Factor(
        name="dist_scale",
        kind="visual",
        values=tuple(str(k) for k in range(N_DIST_SCALE_LEVELS)),
        baseline="0",
        doc=f"k: front and left_top moved back along their optical axis by {DIST_STEP_M}*k m.",
        title="Dist Scale",
        bind=PullBack,
        always_in_id=True,
        alters=MOVED,
    )
)
