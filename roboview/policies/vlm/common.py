"""What the VLM agents share: their config (an OpenAI-compatible endpoint) and 2D → 3D geometry."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from roboview.policies.base import ControlledConfig
from roboview.policies.perception import (
    ELONGATED_ASPECT,
    TOP_FACE_BAND,
    back_project,
    footprint_yaw,
)
from roboview.policies.vlm.client import Endpoint, endpoint_aliases
from roboview.sim.cameras import ALL_CAMERAS, CameraPose

# Around the point the VLM gave: the object's points lie within this xy radius (m) and above this
# height over the table (m); fewer than MIN_POINTS of them and the point missed the object.
OBJECT_RADIUS_M = 0.035
OBJECT_MIN_HEIGHT_M = 0.008
MIN_POINTS = 4


@dataclass
class VLMConfig(ControlledConfig):
    """An agent that asks an OpenAI-compatible chat-completions endpoint about its camera image."""

    # The VLM endpoint the agent asks (--policy.endpoint.base_url, --policy.endpoint.model, ...).
    endpoint: Endpoint = field(default_factory=Endpoint)
    # Scene camera the agent looks through: front, left_top, right_top or wrist (RGB-D; the VLM sees the RGB image).
    camera: str = "front"

    depth = True
    plans_joints = True
    reproducible = False  # the endpoint's answers are not drawn from the episode seed
    # The endpoint's settings were once flags of their own: --policy.model still means
    # --policy.endpoint.model.
    flag_aliases: ClassVar[dict[str, str]] = endpoint_aliases()

    def __post_init__(self) -> None:
        if self.camera not in ALL_CAMERAS:
            raise ValueError(f"unknown camera {self.camera!r}; allowed: {', '.join(ALL_CAMERAS)}")
        self.endpoint.validate("--policy.endpoint.")
        super().__post_init__()

    def observed_cameras(self) -> tuple[str, ...]:
        return (self.camera,)

    def options(self) -> dict[str, Any]:
        # Where the answers come from matters for a resume (recorded flat, as run.json has always held them);
        # the key's variable name, the cache and the request limits do not.
        own = {k: v for k, v in super().options().items() if k != "endpoint"}
        return {"base_url": self.endpoint.base_url, "model": self.endpoint.model, **own}

    @classmethod
    def from_options(cls, settings: dict[str, Any]) -> VLMConfig:
        own = {k: v for k, v in settings.items() if k not in ("base_url", "model")}
        endpoint = Endpoint(
            base_url=settings.get("base_url", Endpoint.base_url), model=settings.get("model", "")
        )
        return cls(endpoint=endpoint, **own)


def check_point(value: Any, key: str, width: int, height: int) -> tuple[float, float] | None:
    """A VLM's [x, y] pixel point (None: the model says it sees none); anything else raises ValueError."""
    if value is None:
        return None
    if not (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) for v in value)
    ):
        raise ValueError(f"{key} must be [x, y] in pixels (or null), got {value!r}")
    x, y = float(value[0]), float(value[1])
    if not (0 <= x < width and 0 <= y < height):
        raise ValueError(f"{key} ({x:g}, {y:g}) lies outside the {width}x{height} image")
    return x, y


def object_from_point(
    point: tuple[float, float], depth: np.ndarray, camera: CameraPose
) -> tuple[np.ndarray, float, float] | None:
    """(center, yaw, symmetry) of the solid under an image point, from depth alone; None if it hits no solid.

    The point is back-projected; the object's surface is every point within OBJECT_RADIUS_M of it in
    xy that stands above the table; its top face gives the center and the footprint's heading.
    """
    points = back_project(depth.astype(np.float64), camera)
    u, v = int(point[0]), int(point[1])
    hit = points[v, u]
    near = np.linalg.norm(points[..., :2] - hit[:2], axis=-1) < OBJECT_RADIUS_M
    solid = points[near & (points[..., 2] > OBJECT_MIN_HEIGHT_M)]
    if len(solid) < MIN_POINTS or solid[:, 2].max() > 0.12:
        return None  # the table, the box's inside, or the arm
    top_z = float(solid[:, 2].max())
    top = solid[solid[:, 2] > top_z - TOP_FACE_BAND]
    face = top if len(top) >= 5 else solid
    yaw, aspect = footprint_yaw(face[:, :2])
    symmetry = np.pi if aspect > ELONGATED_ASPECT else np.pi / 2
    return np.array([*face[:, :2].mean(axis=0), top_z / 2]), yaw, symmetry


def world_point(point: tuple[float, float], depth: np.ndarray, camera: CameraPose) -> np.ndarray:
    u, v = int(point[0]), int(point[1])
    return back_project(depth.astype(np.float64), camera)[v, u]
