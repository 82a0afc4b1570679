"""`scene_text` in LIBERO's scenes: the card with its word, added to LIBERO's MJCF only for an instance that sets it.

LIBERO compiles its scene from robosuite's MJCF. A `TextCard` names an MJCF edit (`edit_xml`: a flat 2D texture, its
material, and a static, contact-free card body in visual group 1, parked) that `LiberoWorld` hands robosuite as its
XML processor for the compile; an instance that does not set the factor compiles LIBERO's own MJCF, untouched, so
LeRobot's `LiberoEnv` episode stays bit for bit what it was. After the reset, `apply` lays the card flat on the table
where agentview's line of sight through `CARD_PIXEL` (a point of the lower middle of its frame, clear of the objects)
first meets a static surface, turned so its text reads upright in the observed frame, and writes the value's word
(roboview.variation.factors.scene_text: the words, the font, the pixels) into the texture. The words follow the
task's instruction (`goal_words`: BASKET and PLATE in the basket tasks).

The fairness gate reads the card through `LiberoCard`: the glyph heights, the pixels of the task's object it hides
(`hidden`) and those of each place of the task's goal (`hidden_goals`: `goal_places`' objects by segmentation with and
without the card; a region of the table, which is no object's, as its site's top face projected by `region_mask`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from roboview.libero.factors import (
    AGENTVIEW,
    VISUAL_GROUP,
    camera_pose,
    goal_places,
    object_geoms,
    target_object,
)
from roboview.variation.factors.scene_text import (
    CARD_M,
    CARD_THICK_M,
    REFERENCE,
    TEXTURE_HW,
    card_image,
    glyph_height,
    goal_words,
    text_of,
)
from roboview.variation.model_edits import rotation, tex_slice

CARD = "scene_text_card"
# Where the card lies: agentview's line of sight through this point of its upright frame (x right, y down, 0–1).
CARD_PIXEL = (0.5, 0.86)


def card_xml(xml: str) -> str:
    """LIBERO's MJCF with the card added: its texture (drawn into after the compile), material and parked body."""
    root = ET.fromstring(xml)
    asset, world = root.find("asset"), root.find("worldbody")
    if asset is None or world is None:
        raise ValueError("LIBERO's MJCF has no <asset> or <worldbody> to add the scene_text card to")
    height, width = TEXTURE_HW
    ET.SubElement(
        asset,
        "texture",
        name=CARD,
        type="2d",
        builtin="flat",
        width=str(height),
        height=str(width),
        rgb1="1 1 1",
    )
    ET.SubElement(asset, "material", name=CARD, texture=CARD)
    body = ET.SubElement(world, "body", name=CARD, pos="0 0 -5")
    size = f"{CARD_M[1] / 2} {CARD_M[0] / 2} {CARD_THICK_M / 2}"
    ET.SubElement(
        body, "geom", name=CARD, type="box", size=size, material=CARD, contype="0", conaffinity="0",
        group=str(VISUAL_GROUP),
    )  # fmt: skip
    return ET.tostring(root, encoding="unicode")


def pixels(value: str, instruction: str) -> np.ndarray:
    """The card texture's pixels for `value` in the task told `instruction`, as the box face maps them."""
    # Turned 180° against RoboView's card: LIBERO's frames reach a policy turned (robosuite reads rows bottom first,
    # LeRobot turns the frame 180°), and the word must read in the frame a policy is handed.
    image = card_image(*text_of(value, goal_words(instruction)))[::-1, ::-1]
    return np.ascontiguousarray(image.transpose(1, 0, 2)[::-1, ::-1])


def _ids(model: mujoco.MjModel) -> tuple[int, int, int]:
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, CARD)
    if body < 0:
        raise RuntimeError("the LIBERO model was compiled without the scene_text card")
    geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, CARD)
    return body, geom, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXTURE, CARD)


def write_texture(world, value: str) -> None:
    """The card's texture set to `value`'s word and uploaded to the live render context."""
    model, (_, _, tex) = world.model, _ids(world.model)
    model.tex_data[tex_slice(model, tex)] = pixels(value, world.task.language).reshape(-1)
    ctx = world.render_context
    ctx.gl_ctx.make_current()
    mujoco.mjr_uploadTexture(model, ctx.con, tex)


def lay_card(world) -> None:
    """The card flat on the first static surface agentview sees through CARD_PIXEL, its text upright there."""
    model, data = world.model, world.data
    body, geom, _ = _ids(model)
    pos, quat = camera_pose(world, AGENTVIEW)
    rot = rotation(quat)  # columns: right, up, backward
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, AGENTVIEW)
    half = np.tan(np.radians(model.cam_fovy[cam]) / 2)
    u, v = CARD_PIXEL
    ray = rot @ np.array([(2 * u - 1) * half, (1 - 2 * v) * half, -1.0])
    ray /= np.linalg.norm(ray)
    groups = np.zeros(6, np.uint8)
    groups[VISUAL_GROUP] = 1
    hit, start = np.zeros(1, np.int32), pos.copy()
    for _ in range(64):  # past the robot and the objects: the card lies on the table (or the floor)
        dist = mujoco.mj_ray(model, data, start, ray, groups, 1, -1, hit)
        if hit[0] < 0:
            raise RuntimeError("agentview's line of sight to the scene_text card meets no static surface")
        start = start + ray * (dist + 1e-4)
        if model.body_weldid[model.geom_bodyid[hit[0]]] == 0 and hit[0] != geom:
            break
    up = rot[:, 1] - rot[:, 1] @ [0, 0, 1.0] * np.array([0, 0, 1.0])
    right = np.cross(up / np.linalg.norm(up), [0, 0, 1.0])
    frame = np.column_stack([-up / np.linalg.norm(up), right, [0, 0, 1.0]])
    body_quat = np.zeros(4)
    mujoco.mju_mat2Quat(body_quat, frame.reshape(9))
    model.body_pos[body] = start + [0, 0, CARD_THICK_M / 2 + 1e-4]
    model.body_quat[body] = body_quat


@dataclass(frozen=True)
class TextCard:
    """The applier of `scene_text=value` in LIBERO's scenes (`World.appliers`)."""

    value: str
    # The texture's pixels change with the value: the world compiles a new model after such an episode, as after a
    # table texture (the render context keeps texture state a restore in place does not undo).
    in_place = False

    def __post_init__(self) -> None:
        text_of(self.value, goal_words("the basket"))  # validates the value

    @staticmethod
    def edit_xml(xml: str) -> str:
        return card_xml(xml)

    def apply(self, world) -> None:
        lay_card(world)
        write_texture(world, self.value)


class LiberoCard:
    """The card of a LIBERO scene compiled with it, as the gate and the isolation certificate read it
    (`LiberoTaskEnv.text_card`)."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self._seg: mujoco.Renderer | None = None
        # The last segmentations per camera, with the state they were rendered in: the gate asks `hidden` and
        # `hidden_goals` of one state, and both read the same two renders.
        self._segments: dict[str, tuple[tuple, tuple[np.ndarray, np.ndarray]]] = {}

    @property
    def world(self):
        return self.env.libero_world

    def geometry(self) -> list[float]:
        model, (body, geom, _) = self.world.model, _ids(self.world.model)
        return [*model.body_pos[body], *model.body_quat[body], *model.geom_size[geom]]

    def glyph_heights(self, cameras: list[str], rgb: dict[str, np.ndarray]) -> dict[str, float]:
        """Per camera, the text's glyph height: the live state rendered with the word and blank (an observation's
        frames are sampled at a physics substep of the last step, not the live state)."""
        value = self.env.instance.get("scene_text")
        with self.world.own_gl():
            shown = {cam: self.env.render_camera(cam) for cam in cameras}
            write_texture(self.world, REFERENCE)
            try:
                blank = {cam: self.env.render_camera(cam) for cam in cameras}
            finally:
                write_texture(self.world, value)
        return {cam: glyph_height(shown[cam], blank[cam]) for cam in cameras}

    def hidden(self, cameras: list[str]) -> dict[str, int]:
        """Per camera, the pixels of the task's object (`target_object`) the card covers: those it shows without the
        card and not with it."""
        figure = object_geoms(self.world, target_object(self.world))
        out = {}
        for cam in cameras:
            shown, alone = self.segments(cam)
            out[cam] = int((np.isin(alone, figure) & ~np.isin(shown, figure)).sum())
        return out

    def hidden_goals(self, cameras: list[str]) -> dict[str, dict[str, tuple[int, int]]]:
        """Per camera, per place of the task's goal (`goal_places`: the basket, the plate, the stove…), the pixels
        the card covers and those the place shows without the card. An object's are its visual geoms' pixels, as
        `hidden` counts the object's; a region of no object (a table's) is its site's top face seen by the camera
        (`region_mask`), and the card covers the pixels of it where the card shows (the card lies on the table, the
        region is the table's: what stands in front of the card stands in front of the region)."""
        world, card = self.world, _ids(self.world.model)[1]
        places = goal_places(world)
        objects = {**world.inner.fixtures_dict, **world.inner.objects_dict}
        out = {}
        for cam in cameras:
            shown, alone = self.segments(cam)
            out[cam] = {}
            for place in places:
                if place in objects:
                    figure = object_geoms(world, place)
                    seen = np.isin(alone, figure)
                    out[cam][place] = (int((seen & ~np.isin(shown, figure)).sum()), int(seen.sum()))
                else:
                    seen = region_mask(world, place, self.env.camera_ids()[cam], shown.shape)
                    out[cam][place] = (int((seen & (shown == card)).sum()), int(seen.sum()))
        return out

    def segments(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """`camera`'s geom ids per pixel (-1: none), with the card and without it (made transparent); rendered once
        per state of the scene (its model, its bodies' and geoms' placement, and the joints' positions)."""
        model = self.world.model
        placement = (model.body_pos, model.body_quat, model.geom_pos, model.geom_quat, model.geom_size)
        state = (id(model), self.world.data.qpos.tobytes(), *(a.tobytes() for a in placement))
        cached = self._segments.get(camera)
        if cached is None or cached[0] != state:
            self._segments[camera] = cached = (state, self._render_segments(camera))
        return cached[1]

    def _render_segments(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        model, (_, geom, _) = self.world.model, _ids(self.world.model)
        rgba = model.geom_rgba[geom].copy()
        shown = self._geom_ids(camera)
        model.geom_rgba[geom, 3] = 0.0
        try:
            alone = self._geom_ids(camera)
        finally:
            model.geom_rgba[geom] = rgba
        return shown, alone

    def _geom_ids(self, camera: str) -> np.ndarray:
        model = self.world.model
        if self._seg is None or self._seg.model is not model:
            self._seg = mujoco.Renderer(model, self.env.image_size, self.env.image_size)
            self._seg.enable_segmentation_rendering()
            self._option = mujoco.MjvOption()
            self._option.geomgroup[:] = 0
            self._option.geomgroup[VISUAL_GROUP] = 1
        cam = self.env.camera_ids()[camera]
        self._seg.update_scene(self.world.data, camera=cam, scene_option=self._option)
        seg = self._seg.render()
        return np.where(seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, seg[..., 0], -1)


def region_mask(world, site: str, camera: int, shape: tuple[int, ...]) -> np.ndarray:
    """The pixels of `camera`'s frame (top row first, as mujoco.Renderer's) inside the top face of LIBERO's region
    `site` (a box site: its x-y rectangle), projected through the camera's pinhole; none where a corner lies behind
    the camera."""
    model, data = world.model, world.data
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
    if sid < 0:
        raise ValueError(f"the goal's place {site!r} is neither an object nor a site of the LIBERO model")
    rot, (sx, sy, sz) = data.site_xmat[sid].reshape(3, 3), model.site_size[sid]
    corners = (
        data.site_xpos[sid]
        + np.array([[x, y, sz] for x, y in ((-sx, -sy), (sx, -sy), (sx, sy), (-sx, sy))]) @ rot.T
    )
    local = (corners - data.cam_xpos[camera]) @ data.cam_xmat[camera].reshape(
        3, 3
    )  # camera axes: right, up, back
    height, width = shape[:2]
    if (local[:, 2] >= 0).any():
        return np.zeros((height, width), bool)
    focal = height / 2 / np.tan(np.radians(model.cam_fovy[camera]) / 2)
    px = np.column_stack(
        [width / 2 + focal * local[:, 0] / -local[:, 2], height / 2 - focal * local[:, 1] / -local[:, 2]]
    )
    cols, rows = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    sides = []
    for a, b in zip(px, np.roll(px, -1, axis=0), strict=True):  # the convex outline's edges, in turn
        sides.append((b[0] - a[0]) * (rows - a[1]) - (b[1] - a[1]) * (cols - a[0]))
    sides = np.stack(sides)
    return (sides >= 0).all(axis=0) | (sides <= 0).all(axis=0)
