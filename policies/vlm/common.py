"""What the VLM agents share: their config (an OpenAI-compatible endpoint) and 2D → 3D geometry."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from policies.base import PolicyConfig
from policies.perception import (
    ELONGATED_ASPECT,
    TOP_FACE_BAND,
    back_project,
    footprint_yaw,
)
from policies.vlm.client import Endpoint, default_cache_dir
from roboview_data.sim.cameras import ALL_CAMERAS, CameraPose

# Around the point the VLM gave: the object's points lie within this xy radius (m) and above this
# height over the table (m); fewer than MIN_POINTS of them and the point missed the object.
OBJECT_RADIUS_M = 0.035
OBJECT_MIN_HEIGHT_M = 0.008
MIN_POINTS = 4


@dataclass
class VLMConfig(PolicyConfig):
    """An agent that asks an OpenAI-compatible chat-completions endpoint about its camera image."""

    # Base URL of the API: https://api.openai.com/v1, http://localhost:8000/v1 (vLLM),
    # http://localhost:11434/v1 (Ollama), or pipelines.serve_vlm's stand-in.
    base_url: str = "http://127.0.0.1:8000/v1"
    # Model name on that endpoint (gpt-4o, qwen-vl-max, Qwen/Qwen2.5-VL-7B-Instruct, ...).
    model: str = ""
    # Name of the environment variable holding the API key (the key itself never goes in a file).
    api_key_env: str = "OPENAI_API_KEY"
    # Seconds per request; retries of 429 / 5xx / timeouts with exponential backoff.
    timeout_s: float = 60.0
    # Retries of a request answered 429 / 5xx or timed out, with exponential backoff, before it fails.
    max_retries: int = 4
    # Requests in flight to this endpoint at once, across every worker process on this machine.
    max_in_flight: int = 4
    # Answer cache: a rerun asks nothing twice ("" turns it off); default $XDG_CACHE_HOME/roboview/vlm.
    cache_dir: str = field(default_factory=default_cache_dir)
    # Scene camera the agent looks through (RGB-D; the VLM sees the RGB image).
    camera: str = "front"

    depth = True

    def __post_init__(self) -> None:
        if self.camera not in ALL_CAMERAS:
            raise ValueError(f"unknown camera {self.camera!r}; allowed: {', '.join(ALL_CAMERAS)}")
        self.endpoint().validate()
        super().__post_init__()

    def endpoint(self) -> Endpoint:
        return Endpoint(self.base_url, self.model, self.api_key_env, self.timeout_s, self.max_retries,
                        self.max_in_flight, self.cache_dir)

    def observed_cameras(self) -> tuple[str, ...]:
        return (self.camera,)

    def options(self) -> dict[str, Any]:
        # Where the answers come from matters for a resume; the key's variable name and the cache do not.
        skip = ("api_key_env", "cache_dir", "timeout_s", "max_retries", "max_in_flight")
        return {k: v for k, v in super().options().items() if k not in skip}


def check_point(value: Any, key: str, width: int, height: int) -> tuple[float, float] | None:
    """A VLM's [x, y] pixel point (None: the model says it sees none); anything else raises ValueError."""
    if value is None:
        return None
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)):
        raise ValueError(f"{key} must be [x, y] in pixels (or null), got {value!r}")
    x, y = float(value[0]), float(value[1])
    if not (0 <= x < width and 0 <= y < height):
        raise ValueError(f"{key} ({x:g}, {y:g}) lies outside the {width}x{height} image")
    return x, y


def object_from_point(point: tuple[float, float], depth: np.ndarray, camera: CameraPose
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
