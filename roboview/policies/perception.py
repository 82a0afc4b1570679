"""Classic-vision perception for the `vision` policy: one RGB-D frame → object and box in 3D.

No simulator state is read here: the inputs are an RGB image, a depth image (metres along the
optical axis, as `mujoco.Renderer` renders it) and the camera's calibration (world pose + fovy).
Every pixel is back-projected with the pinhole model, then labelled by colour:

- **table**: the image's dominant colour (the mode of a coarse CIELAB histogram), matched with a
  tight chroma and a loose lightness tolerance, because shading changes lightness across the table
  far more than it changes hue;
- **box**: the instruction says "the yellow box", so every pixel in a fixed yellow HSV range is
  box-coloured and the largest such blob is the box;
- **robot**: excluded by where it is, not by colour: it stands at the world origin (the agent's
  own mount point) and rises above the table, so points near its base or high above the table
  are never candidates;
- **object**: the most salient compact blob left, i.e. the one whose colour is farthest from the
  table's, among blobs of a graspable physical size.

These rules are deliberately colour-driven, so the agent inherits colour and viewpoint biases:
yellow/gold objects are swallowed by the box mask, table-coloured (mid grey) objects vanish into
the table, and far or oblique cameras leave only a few pixels of the object's top face.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from roboview.sim.cameras import CameraPose

# Table model: chroma (a*, b*) distance and lightness (L*) tolerance to the dominant colour.
TABLE_CHROMA_TOL = 8.0
TABLE_LIGHTNESS_TOL = 25.0
# Coarse CIELAB histogram bins (L*, a*, b*) used to find the dominant colour.
HIST_BIN = np.array([10.0, 4.0, 4.0])
# "Yellow" in OpenCV HSV (hue 0–180): 40°–70°, clearly saturated and not dark.
YELLOW_LOW = np.array([20, 115, 64], dtype=np.uint8)
YELLOW_HIGH = np.array([35, 255, 255], dtype=np.uint8)
# The push task's marked zone: a saturated light blue (hue ≈ 215°), flat on the table.
ZONE_LOW = np.array([98, 110, 110], dtype=np.uint8)
ZONE_HIGH = np.array([118, 255, 255], dtype=np.uint8)
# Robot exclusion: points higher than this above the table or this close to the arm's base (m).
ROBOT_CLEARANCE_Z = 0.10
ROBOT_BASE_RADIUS = 0.25
# Points below this height are off the table (the floor beyond its edge).
TABLE_SURFACE_MIN_Z = -0.01
# A graspable "small object": footprint at most this long (m) and at least this many pixels
# per 224×224 image (scaled with image area).
MAX_OBJECT_EXTENT = 0.10
MIN_OBJECT_PIXELS_224 = 6
# Compactness (blob area / its min-area rectangle) below which a blob is a sliver, not a solid.
MIN_COMPACTNESS = 0.45
# Top-face band (m): points this close to the blob's highest point are its top face.
TOP_FACE_BAND = 0.006
# Footprint aspect ratio above which the object is elongated (yaw matters modulo π, not π/2).
ELONGATED_ASPECT = 1.25
MIN_BOX_PIXELS_224 = 80


class PerceptionError(RuntimeError):
    """Perception could not find what the task needs; `reason` is recorded as the failure."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class Perception:
    """What the agent believes about the scene, in world coordinates (m, rad)."""

    # Center of the object (xy from its top face, z = half its height above the table).
    object_pos: np.ndarray
    # Heading of the object's shorter footprint side (the axis the fingers should close along).
    object_yaw: float
    # Rotational symmetry about z assumed for the grasp: π/2 for square-ish footprints, else π.
    symmetry: float
    # Center of the target's footprint (the box, the zone; None for a task without a target).
    box_xy: np.ndarray | None
    # Pixels of the chosen object blob and of the box, and the object's mean ΔE to the table.
    object_pixels: int
    box_pixels: int
    saliency: float


def back_project(depth: np.ndarray, camera: CameraPose) -> np.ndarray:
    """World xyz (H×W×3) of every pixel, from z-depth and the pinhole model of a MuJoCo camera."""
    h, w = depth.shape
    focal = (h / 2) / np.tan(np.deg2rad(camera.fovy) / 2)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    # MuJoCo cameras look along −z with +y up; image rows grow downward.
    cam = np.stack([(u - w / 2) / focal * depth, -(v - h / 2) / focal * depth, -depth], axis=-1)
    return cam @ camera.rotation.T + np.asarray(camera.pos)


def to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (L* 0–100, a*, b*) of an sRGB uint8 image."""
    return cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)


def dominant_color(lab: np.ndarray) -> np.ndarray:
    """Median Lab of the most populated coarse histogram bin: the table, which fills most views."""
    flat = lab.reshape(-1, 3)
    bins = np.floor(flat / HIST_BIN).astype(np.int64)
    _, inverse, counts = np.unique(bins, axis=0, return_inverse=True, return_counts=True)
    return np.median(flat[inverse.ravel() == np.argmax(counts)], axis=0)


def table_mask(lab: np.ndarray, table_lab: np.ndarray) -> np.ndarray:
    chroma = np.linalg.norm(lab[..., 1:] - table_lab[1:], axis=-1)
    return (chroma < TABLE_CHROMA_TOL) & (np.abs(lab[..., 0] - table_lab[0]) < TABLE_LIGHTNESS_TOL)


def yellow_mask(rgb: np.ndarray) -> np.ndarray:
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    return cv2.inRange(hsv, YELLOW_LOW, YELLOW_HIGH) > 0


def zone_mask(rgb: np.ndarray) -> np.ndarray:
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    return cv2.inRange(hsv, ZONE_LOW, ZONE_HIGH) > 0


def robot_mask(points: np.ndarray) -> np.ndarray:
    """Where the robot can be: above the table's object layer or around its own base."""
    near_base = np.linalg.norm(points[..., :2], axis=-1) < ROBOT_BASE_RADIUS
    return (points[..., 2] > ROBOT_CLEARANCE_Z) | near_base


def _components(mask: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    return cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)[:3]


def locate_box(yellow: np.ndarray, points: np.ndarray, min_pixels: int) -> tuple[np.ndarray, int]:
    """Center of the largest yellow blob's 3D footprint (robust extents of its points)."""
    n, labels, stats = _components(yellow)
    if n <= 1 or stats[1:, cv2.CC_STAT_AREA].max() < min_pixels:
        raise PerceptionError("box not found")
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    xy = points[labels == best][:, :2]
    # Walls, rims and floor together span the whole footprint; the mean would lean toward the
    # faces the camera sees, the middle of the extents does not.
    lo, hi = np.percentile(xy, [2, 98], axis=0)
    return (lo + hi) / 2, int(stats[best, cv2.CC_STAT_AREA])


def footprint_yaw(xy: np.ndarray) -> tuple[float, float]:
    """(heading of the shorter side, aspect ratio) of the min-area rectangle around `xy` (m)."""
    rect = cv2.minAreaRect((xy * 1000.0).astype(np.float32))
    corners = cv2.boxPoints(rect)
    edges = [corners[1] - corners[0], corners[2] - corners[1]]
    lengths = [float(np.linalg.norm(e)) for e in edges]
    short = edges[int(np.argmin(lengths))]
    aspect = max(lengths) / max(min(lengths), 1e-6)
    return float(np.arctan2(short[1], short[0])), aspect


def locate_object(
    candidates: np.ndarray, lab: np.ndarray, table_lab: np.ndarray, points: np.ndarray, min_pixels: int
) -> tuple[np.ndarray, float, float, int, float]:
    """The most salient compact blob of graspable size: (center, yaw, symmetry, pixels, ΔE)."""
    n, labels, stats = _components(candidates)
    delta_e = np.linalg.norm(lab - table_lab, axis=-1)
    best, best_score = 0, 0.0
    for i in range(1, n):
        area = int(stats[i, cv2.CC_STAT_AREA])
        if area < min_pixels:
            continue
        pts = points[labels == i]
        extent = pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0)
        if extent.max() > MAX_OBJECT_EXTENT:
            continue
        ys, xs = np.nonzero(labels == i)
        (_, _), (rw, rh), _ = cv2.minAreaRect(np.column_stack([xs, ys]).astype(np.float32))
        compactness = area / max((rw + 1) * (rh + 1), 1.0)
        if compactness < MIN_COMPACTNESS:
            continue
        score = float(delta_e[labels == i].mean()) * compactness
        if score > best_score:
            best, best_score = i, score
    if best == 0:
        raise PerceptionError("object not found")
    pts = points[labels == best]
    top_z = float(pts[:, 2].max())
    top = pts[pts[:, 2] > top_z - TOP_FACE_BAND]
    # The top face's center is the object's center in xy whatever side faces the camera.
    face = top if len(top) >= 5 else pts
    yaw, aspect = footprint_yaw(face[:, :2])
    symmetry = np.pi if aspect > ELONGATED_ASPECT else np.pi / 2
    center = np.array([*face[:, :2].mean(axis=0), top_z / 2])
    return center, yaw, symmetry, int(stats[best, cv2.CC_STAT_AREA]), float(delta_e[labels == best].mean())


TARGET_MASKS = {"box": yellow_mask, "zone": zone_mask}


def perceive(
    rgb: np.ndarray, depth: np.ndarray, camera: CameraPose, target: str | None = "box"
) -> Perception:
    """Find the small object and the task's target — the yellow box, the push task's marked zone, or
    nothing (None) — in one RGB-D frame; raise PerceptionError if not. `box_xy` is the target's center."""
    if target is not None and target not in TARGET_MASKS:
        raise ValueError(f"perception knows no target {target!r}; allowed: {', '.join(TARGET_MASKS)} or None")
    if rgb.shape[:2] != depth.shape:
        raise ValueError(f"rgb {rgb.shape} and depth {depth.shape} differ in size")
    scale = rgb.shape[0] * rgb.shape[1] / 224**2
    points = back_project(depth.astype(np.float64), camera)
    lab = to_lab(rgb)
    table_lab = dominant_color(lab)
    if target is None:
        yellow, box_xy, box_pixels = np.zeros(rgb.shape[:2], bool), None, 0
    else:
        yellow = TARGET_MASKS[target](rgb)
        try:
            box_xy, box_pixels = locate_box(yellow, points, max(1, round(MIN_BOX_PIXELS_224 * scale)))
        except PerceptionError:
            raise PerceptionError(f"{target} not found") from None
    on_table = points[..., 2] > TABLE_SURFACE_MIN_Z
    candidates = on_table & ~table_mask(lab, table_lab) & ~yellow & ~robot_mask(points)
    center, yaw, symmetry, pixels, saliency = locate_object(
        candidates, lab, table_lab, points, max(1, round(MIN_OBJECT_PIXELS_224 * scale))
    )
    return Perception(center, yaw, symmetry, box_xy, pixels, box_pixels, saliency)
