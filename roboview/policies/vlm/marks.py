"""Numbered marks drawn on an image (MOKA's mark-based visual prompting), and how they look."""

from __future__ import annotations

import cv2
import numpy as np

FONT = cv2.FONT_HERSHEY_SIMPLEX
FONT_SCALE = 0.45
FONT_THICKNESS = 1
MARK_RGB = (255, 0, 255)
MARK_RADIUS = 9
# Images are upscaled by this factor before marking, so numbers stay legible on small renders.
UPSCALE = 4


def draw_marks(rgb: np.ndarray, points: list[tuple[float, float]]) -> np.ndarray:
    """`rgb` upscaled by UPSCALE with mark i+1 (a magenta disk, white number) at points[i] (original pixels)."""
    out = cv2.resize(rgb, (rgb.shape[1] * UPSCALE, rgb.shape[0] * UPSCALE), interpolation=cv2.INTER_NEAREST)
    out = np.ascontiguousarray(out)
    for i, (x, y) in enumerate(points, start=1):
        cx, cy = int(round(x * UPSCALE)), int(round(y * UPSCALE))
        cv2.circle(out, (cx, cy), MARK_RADIUS, MARK_RGB, -1, cv2.LINE_8)
        text = str(i)
        (tw, th), _ = cv2.getTextSize(text, FONT, FONT_SCALE, FONT_THICKNESS)
        cv2.putText(
            out,
            text,
            (cx - tw // 2, cy + th // 2),
            FONT,
            FONT_SCALE,
            (255, 255, 255),
            FONT_THICKNESS,
            cv2.LINE_8,
        )
    return out
