"""Classic 2D image analysis shared by the stand-in model and the classic grounding backend.

From an RGB image alone: the table is the image's dominant color, the box the largest yellow blob,
candidate objects the compact non-table, non-yellow blobs of a small object's size, most salient
(farthest from the table's color) first. No depth, no calibration, no simulator state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from roboview.policies.perception import dominant_color, table_mask, to_lab, yellow_mask
from roboview.policies.vlm.marks import MARK_RGB
from roboview.variation.colors import basic_category, srgb_to_lab

# Object blob: at least this many pixels per 224² image, at most this share of the image.
MIN_OBJECT_PIXELS_224 = 6
MAX_OBJECT_SHARE = 0.02
MIN_COMPACTNESS = 0.45
MIN_BOX_PIXELS_224 = 80
# Marks drawn by the MOKA agent (roboview.policies.vlm.moka): filled circles of this color with a white number.


@dataclass(frozen=True)
class Blob:
    center: tuple[float, float]  # (x, y) pixels
    pixels: int
    rgb: tuple[float, float, float]  # mean sRGB 0–1
    bbox: tuple[int, int, int, int]  # x, y, w, h
    mask: np.ndarray | None = field(default=None, compare=False, repr=False)  # H×W bool


def components(mask: np.ndarray):
    return cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)[:4]


def find_box(rgb: np.ndarray) -> Blob | None:
    n, labels, stats, _ = components(yellow_mask(rgb))
    scale = rgb.shape[0] * rgb.shape[1] / 224**2
    if n <= 1 or stats[1:, cv2.CC_STAT_AREA].max() < MIN_BOX_PIXELS_224 * scale:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, w, h = (int(v) for v in stats[best, :4])
    mean = rgb[labels == best].mean(axis=0) / 255.0
    return Blob(
        (x + w / 2, y + h / 2),
        int(stats[best, cv2.CC_STAT_AREA]),
        tuple(mean.tolist()),
        (x, y, w, h),
        labels == best,
    )


def find_objects(rgb: np.ndarray) -> list[Blob]:
    """Compact, non-table, non-yellow blobs of a small object's size, most salient first."""
    lab = to_lab(rgb)
    table_lab = dominant_color(lab)
    magenta = np.all(rgb == MARK_RGB, axis=-1)
    candidates = ~table_mask(lab, table_lab) & ~yellow_mask(rgb) & ~magenta
    n, labels, stats, _ = components(candidates)
    h, w = rgb.shape[:2]
    scale = h * w / 224**2
    delta_e = np.linalg.norm(lab - table_lab, axis=-1)
    scored = []
    for i in range(1, n):
        x, y, bw, bh, area = (int(v) for v in stats[i])
        if area < MIN_OBJECT_PIXELS_224 * scale or area > MAX_OBJECT_SHARE * h * w:
            continue
        if x == 0 or y == 0 or x + bw >= w or y + bh >= h:
            continue  # cut by the frame: the table's edge, the floor, the arm
        compactness = area / ((bw + 1) * (bh + 1))
        if compactness < MIN_COMPACTNESS:
            continue
        mask = labels == i
        ys, xs = np.nonzero(mask)
        mean = rgb[mask].mean(axis=0) / 255.0
        blob = Blob((float(xs.mean()), float(ys.mean())), area, tuple(mean.tolist()), (x, y, bw, bh), mask)
        scored.append((float(delta_e[mask].mean()) * compactness, blob))
    return [b for _, b in sorted(scored, key=lambda sb: -sb[0])]


def color_word(rgb: tuple[float, float, float]) -> str:
    """The basic color category (Berlin–Kay) of a rendered color."""
    return basic_category(tuple(srgb_to_lab(np.asarray(rgb)).tolist()))


def shape_word(blob: Blob) -> str:
    x, y, w, h = blob.bbox
    return "cube" if max(w, h) / max(min(w, h), 1) < 1.4 else "block"


def position_word(blob: Blob, width: int) -> str:
    x = blob.center[0] / width
    return "left" if x < 0.4 else "right" if x > 0.6 else "normal"
