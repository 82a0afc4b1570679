"""The classic-CV stand-in "model" behind `roboview.pipelines.serve_vlm`: NOT a VLM.

It answers the RoboView agents' requests — image points, a plan with object descriptions, a mark
choice, a scene parse, the fairness yes/no — from the image it is sent, with classic computer vision
(the table is the image's dominant color, the box is the largest yellow blob, the object the most
salient compact blob left; marks are read back by template matching the digits the agent drew). It
never sees simulator state, depth or calibration. It exists so that the whole VLM path (client,
agents, SGL, fairness screen, caching, failures) runs and is measured on a machine that reaches no
VLM; every table labels its results as the classic-CV stand-in.
"""

from __future__ import annotations

import functools
import json
import re

import cv2
import numpy as np

from roboview.policies.vlm.blobs import (
    color_word,
    components,
    find_box,
    find_objects,
    position_word,
    shape_word,
)
from roboview.policies.vlm.marks import MARK_RGB
from roboview.policies.vlm.prompts import kind_of
from roboview.variation.colors import delta_e_2000, srgb_to_lab

MODEL_NAME = "roboview-classic-cv-standin"


def read_marks(rgb: np.ndarray) -> dict[int, tuple[float, float]]:
    """Mark number → center (x, y): magenta disks, their white digits matched against cv2's own glyphs."""
    magenta = np.all(rgb == MARK_RGB, axis=-1)
    n, labels, stats, centroids = components(magenta)
    marks = {}
    for i in range(1, n):
        x, y, w, h = (int(v) for v in stats[i, :4])
        crop = rgb[y : y + h, x : x + w]
        white = np.all(crop > 200, axis=-1).astype(np.uint8)
        number = _match_number(white)
        if number is not None:
            marks[number] = (float(centroids[i][0]), float(centroids[i][1]))
    return marks


@functools.cache
def _digit_templates() -> dict[int, np.ndarray]:
    """Binary glyphs of the numbers 1–99 as the MOKA agent draws them, cropped (rendered once per process)."""
    from roboview.policies.vlm.marks import FONT, FONT_SCALE, FONT_THICKNESS

    out = {}
    for number in range(1, 100):
        text = str(number)
        (tw, th), _ = cv2.getTextSize(text, FONT, FONT_SCALE, FONT_THICKNESS)
        canvas = np.zeros((th + 8, tw + 8), np.uint8)
        cv2.putText(canvas, text, (4, th + 4), FONT, FONT_SCALE, 1, FONT_THICKNESS, cv2.LINE_8)
        cy, cx = np.nonzero(canvas)
        out[number] = canvas[cy.min() : cy.max() + 1, cx.min() : cx.max() + 1]
    return out


def _match_number(white: np.ndarray) -> int | None:
    if white.sum() == 0:
        return None
    ys, xs = np.nonzero(white)
    glyph = white[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    best, best_score = None, -1.0
    for number, template in _digit_templates().items():
        if abs(template.shape[1] - glyph.shape[1]) > 2 or abs(template.shape[0] - glyph.shape[0]) > 2:
            continue
        resized = cv2.resize(glyph, (template.shape[1], template.shape[0]), interpolation=cv2.INTER_NEAREST)
        score = float((resized == template).mean())
        if score > best_score:
            best, best_score = number, score
    return best if best_score > 0.8 else None


def _spans(prompt: str) -> list[tuple[int, int]]:
    """The mark ranges a MOKA prompt names, in order: "Marks 1-5 ...; marks 6-10 ..." → [(1, 5), (6, 10)]."""
    return [(int(a), int(b or a)) for a, b in re.findall(r"[Mm]arks? (\d+)(?:-(\d+))?", prompt)]


def _as_instructed(prompt: str, blobs: list) -> list:
    """Candidates with the one the instruction names first: when the instruction names a colour
    ("the small red cube"), the blob closest to it (CIELAB ΔE2000); otherwise saliency order."""
    from roboview.policies.vlm.grounding import named_color

    quoted = re.search(r'Instruction: "([^"]*)"', prompt)
    # The colour of the object to move, not of the target ("the yellow box").
    subject = re.sub(r"\b(\w+\s+)?(box|container|bin|basket|tray)\b", "", quoted.group(1)) if quoted else ""
    named = named_color(subject) if subject else None
    if named is None or not blobs:
        return blobs
    return sorted(blobs, key=lambda b: float(delta_e_2000(srgb_to_lab(np.asarray(b.rgb)), named[1])))


class ClassicCVModel:
    """Answers the RoboView prompts about one image with classic CV; the reply text is JSON."""

    name = MODEL_NAME

    def answer(self, prompt: str, images: list[np.ndarray]) -> str:
        kind = kind_of(prompt)
        if kind is None or not images:
            return (
                "I am RoboView's classic-CV stand-in and only answer the RoboView agents' own prompts "
                "about one attached image."
            )
        return json.dumps(getattr(self, f"_{kind}")(prompt, images[0]))

    def _points(self, prompt: str, rgb: np.ndarray) -> dict:
        box, objects = find_box(rgb), _as_instructed(prompt, find_objects(rgb))
        return {
            "object_point": [round(v, 1) for v in objects[0].center] if objects else None,
            "target_point": [round(v, 1) for v in box.center] if box else None,
        }

    def _plan(self, prompt: str, rgb: np.ndarray) -> dict:
        objects = _as_instructed(prompt, find_objects(rgb))
        obj = f"small {color_word(objects[0].rgb)} {shape_word(objects[0])}" if objects else "small object"
        return {"object_description": obj, "target_description": "yellow box"}

    def _marks(self, prompt: str, rgb: np.ndarray) -> dict:
        # The prompt says which marks lie on the object and which on the target ("Marks 1-5 lie on the
        # object"); the image says where each mark is. Grasp: the object mark nearest the middle of the
        # object's marks. Place: the target mark nearest the middle of the yellow box.
        marks = read_marks(rgb)
        spans = _spans(prompt)
        if not marks or len(spans) < 2:
            return {"grasp_mark": None, "place_mark": None}
        obj_ids = [m for m in range(spans[0][0], spans[0][1] + 1) if m in marks]
        target_ids = [m for m in range(spans[1][0], spans[1][1] + 1) if m in marks]
        box = find_box(rgb)
        if not obj_ids or not target_ids or box is None:
            return {"grasp_mark": None, "place_mark": None}
        middle = np.mean([marks[m] for m in obj_ids], axis=0)

        def nearest(ids, point):
            return min(ids, key=lambda m: np.hypot(marks[m][0] - point[0], marks[m][1] - point[1]))

        return {"grasp_mark": nearest(obj_ids, middle), "place_mark": nearest(target_ids, box.center)}

    def _scene_parse(self, prompt: str, rgb: np.ndarray) -> list:
        out = []
        objects = find_objects(rgb)
        for i, blob in enumerate(objects[:3]):
            out.append(
                {
                    "ID": len(out) + 1,
                    "object_type": "manipulation object" if i == 0 else "other object",
                    "name": shape_word(blob),
                    "category": [shape_word(blob), "geometry"],
                    "state": "solid",
                    "color": color_word(blob.rgb),
                    "size": "small",
                    "position": position_word(blob, rgb.shape[1]),
                }
            )
        box = find_box(rgb)
        if box is not None:
            out.append(
                {
                    "ID": len(out) + 1,
                    "object_type": "receiver object",
                    "name": "box",
                    "category": ["box", "container", "rectangular shape"],
                    "state": "hollow",
                    "color": "yellow",
                    "size": "normal",
                    "position": position_word(box, rgb.shape[1]),
                }
            )
        return out

    def _fairness(self, prompt: str, rgb: np.ndarray) -> dict:
        box, objects = find_box(rgb), find_objects(rgb)
        if box is None:
            return {"analysis": "No yellow box is visible.", "final_answer": "no"}
        if not objects:
            return {
                "analysis": "A yellow box is visible but no small solid object stands out from the table.",
                "final_answer": "no",
            }
        word = color_word(objects[0].rgb)
        return {
            "analysis": f"A small {word} object ({objects[0].pixels} px) and a yellow box are clearly visible.",
            "final_answer": "yes",
        }
