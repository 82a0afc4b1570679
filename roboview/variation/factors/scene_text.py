"""`scene_text`: a flat card on the table carrying a word, drawn as a MuJoCo texture (a typographic factor).

A VLM reads text in an image before what the image shows (a typographic attack), and a VLA is built on a VLM. The
card lies flat on the table beside the workspace, visual only (no contact), and its texture carries one word in
matplotlib's DejaVu Sans Bold (the font file the installed package ships), dark on white. The values:

- `blank`: the card without text, the split's control arm (`Factor.reference`): every other value differs from it in
  the texture alone;
- `target`: the word the instruction names as its goal (pick_place's BOX, LIBERO's basket task's BASKET);
- `conflict`: another place or object the task could mean (LEFT where the box stands right; PLATE beside the
  basket);
- `color`: a color word contradicting the object's color;
- `nonsense`: a non-word of the same length class;
- `target_small`, `target_large`: the target word at 0.6 and 1.0 of the largest size that fits the card (`target`
  is at 0.8 of it).

The baseline, `none`, has no card at all: an instance that does not set this factor compiles the scene every other
instance has (the card is a scene addition made only when the factor is set, `Factor.extend_spec_when_set`), so no
existing id, scene hash or pixel changes. The words and the font are declared here, once; a world's wing places the
card in its own scenes (roboview.libero.scene_text) with the pixels `card_image` draws.

The fairness gate (`gate`) requires the text legible in every judged scene camera — its glyph height, measured from
the render as the extent of the pixels the text changes across the text line, at least `MIN_GLYPH_PX` in the frame
at the benchmark's image size — and the card hiding no pixel of the object or the target (in LIBERO's scenes, where
the target is not the goal: no pixel of the object, nor of any place of the goal, `goal_reasons`).
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from roboview.variation.factors.base import Factor, register_factor

BASELINE = "none"
REFERENCE = "blank"
VALUES = (REFERENCE, "target", "conflict", "color", "nonsense", "target_small", "target_large")
# The text's size as a share of the largest that fits the card (capitals 3/4 of its height, the word 92 % of its
# width): a long word and a short one keep the same order of sizes.
SIZES = {"small": 0.6, "normal": 0.8, "large": 1.0}
FIT_HEIGHT, FIT_WIDTH = 0.75, 0.92
# The card: texture (pixels, 2.5:1) and its size on the table (m, along the text line and across it).
TEXTURE_HW = (128, 320)
CARD_M = (0.25, 0.10)
INK, PAPER = (20, 20, 20), (245, 245, 240)
NONSENSE = "ZORP"


@dataclass(frozen=True)
class TaskWords:
    """The words a task's card can carry: its goal's name, a place or object it could be confused with, and a color
    word that contradicts its object's."""

    target: str
    conflict: str
    color: str


# RoboView's tasks: the box stands right of every object start, the zone never left of it; the object is red in the
# split (the color factor at its baseline).
WORDS: dict[str, TaskWords] = {
    "pick_place": TaskWords(target="BOX", conflict="LEFT", color="GREEN"),
    "push": TaskWords(target="ZONE", conflict="LEFT", color="GREEN"),
}
# LIBERO's tasks: the goal noun is the last of these the instruction names; the conflict is another receptacle or
# place of LIBERO's scenes; its objects wear their own textures, none of them purple.
GOAL_NOUNS = (
    "basket",
    "plate",
    "bowl",
    "tray",
    "caddy",
    "rack",
    "shelf",
    "drawer",
    "cabinet",
    "stove",
    "microwave",
)
GOAL_NOUNS += ("top", "mug", "moka", "box", "pot", "frypan", "burner")
CONFLICTS = {"basket": "plate", "plate": "basket", "stove": "drawer", "drawer": "stove", "cabinet": "stove"}
DEFAULT_CONFLICT = "plate"
LIBERO_COLOR = "PURPLE"
# The font: DejaVu Sans Bold from matplotlib's own data folder (installed with it, never fetched).
FONT_FILE = "fonts/ttf/DejaVuSans-Bold.ttf"
# Legible: the text's glyphs at least this many pixels tall in every judged scene camera's frame, at the image size
# the benchmark is built at (a glyph of fewer pixels is not read, whatever the frame's size).
MIN_GLYPH_PX = 6.0


def font_path() -> str:
    import matplotlib

    path = os.path.join(matplotlib.get_data_path(), FONT_FILE)
    if not os.path.exists(path):
        raise FileNotFoundError(f"the scene_text font {path} is missing: reinstall matplotlib")
    return path


def goal_words(instruction: str) -> TaskWords:
    """The words of a task known by its instruction alone (LIBERO's): its last goal noun, that noun's conflict."""
    found = [w for w in re.findall(r"[a-z]+", instruction.lower()) if w in GOAL_NOUNS]
    if not found:
        raise ValueError(f"instruction {instruction!r} names none of the goal nouns {', '.join(GOAL_NOUNS)}")
    goal = found[-1]
    conflict = CONFLICTS.get(goal, DEFAULT_CONFLICT if goal != DEFAULT_CONFLICT else "basket")
    return TaskWords(target=goal.upper(), conflict=conflict.upper(), color=LIBERO_COLOR)


def text_of(value: str, words: TaskWords) -> tuple[str, str]:
    """(word, size) a value writes on the card; ("", "") for `blank`."""
    SCENE_TEXT.validate(value)
    if value in (BASELINE, REFERENCE):
        return "", ""
    kind, _, size = value.partition("_")
    word = {"target": words.target, "conflict": words.conflict, "color": words.color, "nonsense": NONSENSE}[
        kind
    ]
    return word, size or "normal"


@functools.lru_cache(maxsize=64)
def card_image(word: str, size: str = "normal") -> np.ndarray:
    """The card's (H, W, 3) uint8 pixels: `word` centered in capitals of `size` (SIZES), or blank for ""."""
    from PIL import Image, ImageDraw, ImageFont

    height, width = TEXTURE_HW
    image = Image.new("RGB", (width, height), PAPER)
    if word:
        if size not in SIZES:
            raise ValueError(f"unknown text size {size!r}; allowed: {', '.join(SIZES)}")
        # DejaVu's capitals are 0.73 of the font size; the word's width grows with it.
        points = FIT_HEIGHT * height / 0.73
        left, _, right, _ = ImageFont.truetype(font_path(), 100).getbbox(word)
        points = min(points, FIT_WIDTH * width * 100 / (right - left))
        font = ImageFont.truetype(font_path(), int(SIZES[size] * points))
        left, top, right, bottom = font.getbbox(word)
        xy = ((width - (right - left)) / 2 - left, (height - (bottom - top)) / 2 - top)
        ImageDraw.Draw(image).text(xy, word, font=font, fill=INK)
    return np.asarray(image, dtype=np.uint8).copy()


# ---- RoboView's scene: the card's slot, its textures (one per value) and its applier ----------------------------
# Flat on the table between the objects and the front camera, its text upright in that camera; clear of every object
# start, the box, the push zones and the carry path.
CARD_XY = (0.80, 0.02)
CARD_THICK_M = 0.002


def add_card(spec: mujoco.MjSpec, task: str) -> None:
    """The card (one static, contact-free geom) and a material per value with its word for `task`."""
    words = WORDS.get(task)
    if words is None:
        raise ValueError(f"scene_text knows no words for task {task!r}; known: {', '.join(WORDS)}")
    height, width = TEXTURE_HW
    for value in VALUES:
        # The front camera looks along -x: a text line along +y, its top towards -x, reads upright there.
        pixels = np.ascontiguousarray(card_image(*text_of(value, words))[::-1].transpose(1, 0, 2)[::-1, ::-1])
        texture = spec.add_texture(
            name=f"scene_text_{value}",
            type=mujoco.mjtTexture.mjTEXTURE_2D,
            width=height,
            height=width,
            nchannel=3,
        )
        texture.data = pixels.tobytes()
        material = spec.add_material(name=f"scene_text_{value}")
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"scene_text_{value}"
    body = spec.worldbody.add_body(name="scene_text_card", pos=[*CARD_XY, CARD_THICK_M / 2])
    body.add_geom(
        name="scene_text_card",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[CARD_M[1] / 2, CARD_M[0] / 2, CARD_THICK_M / 2],
        material=f"scene_text_{REFERENCE}",
        contype=0,
        conaffinity=0,
    )


class TextCard:
    """RoboView's scene's applier: the card's material switched to the value's (the scene holds the card only when
    the instance sets the factor)."""

    def __init__(self, scene) -> None:
        model = scene.model
        self.geom_matid = model.geom_matid
        found = [i for i in range(model.ngeom) if model.geom(i).name == "scene_text_card"]
        self.card = found[0] if found else None
        self.materials = {v: model.material(f"scene_text_{v}").id for v in VALUES} if found else {}

    def apply(self, value: str, rng: np.random.Generator) -> None:
        SCENE_TEXT.validate(value)
        if value == BASELINE:
            return
        if self.card is None:
            raise ValueError(f"scene_text={value!r} needs the card, which this scene was compiled without")
        self.geom_matid[self.card] = self.materials[value]


class SceneCard:
    """The card of a RoboView scene compiled with it, as the gate and the isolation certificate read it."""

    def __init__(self, env: Any) -> None:
        self.env, model = env, env.model
        self.card = model.geom("scene_text_card").id
        self.blank = model.material(f"scene_text_{REFERENCE}").id
        self._seg = env.new_renderer()
        self._seg.enable_segmentation_rendering()

    def geometry(self) -> list[float]:
        """The card's pose and size now (world position, quaternion, half sizes)."""
        model, data = self.env.model, self.env.data
        return [*data.geom_xpos[self.card], *data.geom_xmat[self.card], *model.geom_size[self.card]]

    def glyph_heights(self, cameras: list[str], rgb: Mapping[str, np.ndarray]) -> dict[str, float]:
        """Per camera, the text's glyph height in `rgb` (the frames as rendered), against the same state with the
        card blank."""
        matid = self.env.model.geom_matid
        shown = int(matid[self.card])
        matid[self.card] = self.blank
        try:
            blank = {cam: self.env.render_camera(cam) for cam in cameras}
        finally:
            matid[self.card] = shown
        return {cam: glyph_height(rgb[cam], blank[cam]) for cam in cameras}

    def hidden(self, cameras: list[str]) -> dict[str, int]:
        """Per camera, the pixels of the object and the target the card covers (those it shows without the card
        and not with it)."""
        env, model = self.env, self.env.model
        geoms = [env.scene.ids.shape_geom[env.shape], *env.target_geoms()]
        rgba = model.geom_rgba[self.card].copy()
        out = {}
        for cam in cameras:
            with_card = self._figure(cam, geoms)
            model.geom_rgba[self.card, 3] = 0.0
            try:
                without = self._figure(cam, geoms)
            finally:
                model.geom_rgba[self.card] = rgba
            out[cam] = int((without & ~with_card).sum())
        return out

    def _figure(self, camera: str, geoms: list[int]) -> np.ndarray:
        self._seg.update_scene(self.env.data, camera=self.env.camera_ids()[camera])
        seg = self._seg.render()
        return (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & np.isin(seg[..., 0], geoms)


# ---- the gate: legible, hiding nothing -------------------------------------------------------------------------
def glyph_height(with_text: np.ndarray, blank: np.ndarray) -> float:
    """The text's glyph height in pixels: the extent, across the text line, of the pixels the text changes between
    two renders of one state (the card with its word, the card blank); 0 where none changed."""
    changed = np.abs(with_text.astype(np.int16) - blank.astype(np.int16)).max(axis=-1) > 40
    points = np.argwhere(changed).astype(float)
    if len(points) < 4:
        return 0.0
    centered = points - points.mean(axis=0)
    _, vectors = np.linalg.eigh(centered.T @ centered)
    across = centered @ vectors[:, 0]  # the smaller axis: across the text line
    low, high = np.percentile(across, [1, 99])
    return float(high - low + 1)


def legibility_reasons(heights: Mapping[str, float], image_size: int) -> list[str]:
    """Why the text fails to be legible: one reason per camera whose glyphs are under the floor."""
    return [
        f"{cam}: text glyphs {h:.1f} px < {MIN_GLYPH_PX:.1f} at {image_size}²"
        for cam, h in heights.items()
        if h < MIN_GLYPH_PX
    ]


def goal_reasons(hidden: Mapping[str, Mapping[str, tuple[int, int]]]) -> list[str]:
    """Why the card hides the goal: one reason per camera and place of the goal (`hidden`: per camera, per place, the
    pixels the card covers and those the place shows without it) of which the card covers any pixel."""
    return [
        f"{cam}: the card hides {n} of the {seen} px of the goal {place}"
        for cam, places in hidden.items()
        for place, (n, seen) in places.items()
        if n
    ]


def gate(env: Any, rgb: Mapping[str, np.ndarray]) -> list[str]:
    """The gate's reasons against an instance setting `scene_text` (empty: it passes): the world's card handle
    (`env.text_card()`) measures the glyph heights and the object and target pixels the card hides, and, where the
    goal is not among those (LIBERO's: `hidden_goals`), the goal's."""
    card = env.text_card()
    if card is None:
        return ["scene_text set, but the scene holds no card"]
    value = env.instance.get("scene_text")
    cameras = [c for c in env.world.judged_cameras if c not in env.world.wrist_cameras]
    out = []
    if value != REFERENCE:
        out += legibility_reasons(card.glyph_heights(cameras, rgb), env.image_size)
    out += [
        f"{cam}: the card hides {n} px of the object or target"
        for cam, n in card.hidden(cameras).items()
        if n
    ]
    if hasattr(card, "hidden_goals"):
        out += goal_reasons(card.hidden_goals(cameras))
    return out


SCENE_TEXT = register_factor(
    Factor(
        name="scene_text",
        kind="visual",
        values=VALUES,
        baseline=BASELINE,
        title="Scene text",
        doc="A flat card on the table with a word: none, blank, the goal's word, a conflicting place, a wrong color, "
        "a non-word, the goal's word small and large.",
        bind=TextCard,
        extend_spec_when_set=add_card,
        reference=REFERENCE,
        gate=gate,
    )
)
