"""Visual factors as edits of any compiled MuJoCo model, shared by the worlds whose scenes RoboView does not build
(LIBERO's, Meta-World's): a scene camera orbited, turned or pulled back, and RoboView's `table_texture` values drawn
as texture pixels. Each world's wing applies them to its own model (its cameras, its support surface)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

ORBIT_ELEVATIONS_DEG = (35.0, 50.0, 65.0)  # one ring per elevation above the workspace center
ORBIT_AZIMUTHS_DEG = tuple(np.linspace(-72.0, 72.0, 7))  # about agentview's own azimuth
DIST_STEP_M = 0.05
TEXTURE_PATTERNS = ("checker", "stripes", "noise", "gray")
# RoboView's key-light directions (the `lighting` factor's `top`, `left`, `front`) as every light's direction in a
# world whose lights are its own (world frame; None: the lights keep theirs).
LIGHT_DIRECTIONS = {"top": None, "left": (0.0, -0.8, -0.6), "front": (-0.8, 0.0, -0.6)}


def rotation(quat: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)  # columns: camera right, up, backward


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera rotation (columns right, up, backward) at `eye` looking at `target`, world +z up in the image."""
    backward = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross([0.0, 0.0, 1.0], backward)
    right /= np.linalg.norm(right)
    return np.column_stack([right, np.cross(backward, right), backward])


def orbit_eye(center: np.ndarray, pos: np.ndarray, ring: int, k: int) -> np.ndarray:
    """Orbital pose (`ring`, `k`) of a camera now at `pos`: at its distance from `center`, on ring `ring`'s elevation
    (ORBIT_ELEVATIONS_DEG) and turned ORBIT_AZIMUTHS_DEG[k] about the vertical through `center` from its own
    azimuth."""
    offset = pos - center
    distance = np.linalg.norm(offset)
    azimuth = np.arctan2(offset[1], offset[0]) + np.deg2rad(ORBIT_AZIMUTHS_DEG[k])
    elevation = np.deg2rad(ORBIT_ELEVATIONS_DEG[ring])
    return center + distance * np.array(
        [np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)]
    )


def turned(rot: np.ndarray, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Camera rotation `rot` (columns right, up, backward) turned `yaw_deg` about its own up axis, then `pitch_deg`
    about its own right axis."""
    yaw, pitch = np.deg2rad(yaw_deg), np.deg2rad(pitch_deg)
    r_yaw = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    r_pitch = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    return rot @ r_yaw @ r_pitch


def pulled_back(pos: np.ndarray, rot: np.ndarray, k: int) -> np.ndarray:
    """A camera at `pos` with rotation `rot` moved back DIST_STEP_M·k along its optical axis."""
    return pos + DIST_STEP_M * k * rot[:, 2]


def texture_pixels(pattern: str, height: int, width: int, channels: int) -> np.ndarray:
    """A procedural (height, width, channels) uint8 texture; deterministic (fixed seed for `noise`). `pattern` is
    one of TEXTURE_PATTERNS or a value of RoboView's `table_texture` factor (its colors and pattern, drawn here)."""
    from roboview.variation.factors.table_texture import TEXTURES

    if pattern in TEXTURES:
        return named_texture(pattern, height, width, channels)
    y, x = np.mgrid[0:height, 0:width]
    cells = max(height, width) // 16 or 1
    if pattern == "checker":
        gray = np.where((x // cells + y // cells) % 2, 200, 60)
    elif pattern == "stripes":
        gray = np.where((x // cells) % 2, 220, 90)
    elif pattern == "noise":
        gray = np.random.default_rng(0).integers(40, 220, (height, width))
    elif pattern == "gray":
        gray = np.full((height, width), 128)
    else:
        allowed = (*TEXTURE_PATTERNS, *TEXTURES)
        raise ValueError(f"texture pattern {pattern!r} unknown; allowed: {', '.join(allowed)}")
    return np.repeat(gray[..., None], channels, axis=2).astype(np.uint8)


def named_texture(name: str, height: int, width: int, channels: int) -> np.ndarray:
    """RoboView's `table_texture` value `name` drawn as pixels: its builtin (checker, gradient, flat), its two
    colors, its mark (edge lines, random speckle, crosses) and its repeat count over the texture."""
    from roboview.variation.factors.table_texture import TEXTURES

    builtin, mark, rgb1, rgb2, markrgb, random, repeat = TEXTURES[name]
    y, x = np.mgrid[0:height, 0:width]
    cell = max(1, max(height, width) // (2 * repeat))
    c1, c2, cm = (np.asarray(c, float) for c in (rgb1, rgb2, markrgb))
    if builtin == "checker":
        rgb = np.where(((x // cell + y // cell) % 2)[..., None], c1, c2)
    elif builtin == "gradient":
        rgb = c1 + (c2 - c1) * (y / max(1, height - 1))[..., None]
    else:
        rgb = np.broadcast_to(c1, (height, width, 3)).copy()
    if mark == "edge":
        rgb[(x % cell < 2) | (y % cell < 2)] = cm
    elif mark == "random":
        rgb[np.random.default_rng(0).random((height, width)) < random] = cm
    elif mark == "cross":
        rgb[(np.abs(x % cell - cell // 2) < 2) & (np.abs(y % cell - cell // 2) < cell // 4)] = cm
        rgb[(np.abs(y % cell - cell // 2) < 2) & (np.abs(x % cell - cell // 2) < cell // 4)] = cm
    pixels = np.clip(np.round(rgb * 255), 0, 255).astype(np.uint8)
    return (
        pixels[..., :channels]
        if channels <= 3
        else np.concatenate([pixels, np.full((height, width, channels - 3), 255, np.uint8)], axis=2)
    )


def tex_slice(model: mujoco.MjModel, tex: int) -> slice:
    """Texture `tex`'s pixels in `model.tex_data`."""
    start = model.tex_adr[tex]
    return slice(start, start + model.tex_width[tex] * model.tex_height[tex] * model.tex_nchannel[tex])


def subtree_geoms(model: mujoco.MjModel, root: int, groups: tuple[int, ...]) -> list[int]:
    """The geoms in `groups` of body `root` and every body below it."""
    bodies = {root}
    for body in range(root + 1, model.nbody):  # bodies are stored depth-first: descendants follow the root
        if model.body_parentid[body] in bodies:
            bodies.add(body)
    return [g for g in range(model.ngeom) if model.geom_bodyid[g] in bodies and model.geom_group[g] in groups]


@dataclass(frozen=True)
class Lighting:
    """Every light's diffuse × `scale`; with `direction`, every light points along it (normalised). Applies to any
    object with a compiled `model`."""

    scale: float = 1.0
    direction: tuple[float, float, float] | None = None

    def apply(self, world) -> None:
        model = world.model
        model.light_diffuse[:] = np.clip(model.light_diffuse * self.scale, 0.0, None)
        if self.direction is not None:
            d = np.asarray(self.direction, float)
            model.light_dir[:] = d / np.linalg.norm(d)


def value_args(factor: str, value: str) -> tuple:
    """The arguments a world's applier of `factor` is made with from `value` (`World.appliers`): color → its sRGB
    (0–1), camera_pose → (ring, k), camera_euler → (yaw°, pitch°), dist_scale → (k,), lighting → (diffuse scale, key
    light direction or None); any other factor → the value itself."""
    from roboview.variation.colors import get_color
    from roboview.variation.factors.camera import parse_camera_pose, parse_dist_scale, parse_euler
    from roboview.variation.factors.lighting import INTENSITIES

    if factor == "color":
        return (tuple(get_color(value).rgb),)
    if factor == "camera_pose":
        return parse_camera_pose(value)
    if factor == "camera_euler":
        return parse_euler(value)
    if factor == "dist_scale":
        return (parse_dist_scale(value),)
    if factor == "lighting":
        intensity, direction = value.split("_")
        return INTENSITIES[intensity], LIGHT_DIRECTIONS[direction]
    return (value,)
