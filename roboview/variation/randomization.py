"""Visual domain randomization for demo collection, drawn from continuous ranges.

The benchmark tests a policy on *named* values: 141 CSS colors and 21 orbital camera poses.
Randomizing training data over those exact values would leak the test set into training, so the
ranges here are continuous and contain the test values without singling them out:

- ``color``: the object's sRGB drawn uniformly from the unit cube [0, 1]³.
- ``camera_pose``: the perturbed scene cameras (``front``, ``left_top``) move together to a look-at
  pose at WORKSPACE_CENTER on the continuous surface the three orbital rings lie on: a ring
  coordinate s ~ U(−0.1, 1.1) interpolates (and slightly extrapolates) radius and height between
  the inner and outer ring, azimuth ~ U(−80°, 80°) and the lens fovy ~ U(45°, 50°). The range
  contains every orbital test pose and the original ``left_top`` camera (s ≈ 1.1, azimuth 79°).

The draw uses its own generator stream of the episode seed, so a randomized collection has the
same task contexts, object jitter and expert actions as the context-only collection with the same
`--seed`; only the pixels differ. What was drawn is recorded per episode (`record`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.sim.cameras import (
    BASE_CAMERAS,
    PERTURBED_CAMERAS,
    WORKSPACE_CENTER,
    CameraPose,
    look_at,
)
from roboview.variation.colors import get_color, srgb_to_lab
from roboview.variation.factors import baselines
from roboview.variation.factors.camera import ORBIT_RINGS

RANDOMIZABLE = ("color", "camera_pose")
RING_COORD_RANGE = (-0.1, 1.1)
AZIMUTH_RANGE_DEG = (-80.0, 80.0)
FOVY_RANGE_DEG = (45.0, 50.0)
# Stream of the episode seed the randomization draws from (context and jitter use the seed itself).
STREAM = 0x5EED_DA7A


def validate_randomize(names: list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """The randomized factors in canonical order; unknown or repeated names raise, naming the allowed ones."""
    bad = [n for n in names if n not in RANDOMIZABLE]
    if bad or len(set(names)) != len(names):
        raise ValueError(
            f"randomize={list(names)}: unknown or repeated factor(s) {bad}; "
            f"allowed: {', '.join(RANDOMIZABLE)}"
        )
    return tuple(n for n in RANDOMIZABLE if n in names)


def ring_pose(name: str, s: float, azimuth_deg: float, fovy: float) -> CameraPose:
    """Look-at pose at ring coordinate s (0 = inner ring, 1 = outer ring, linear in radius and height)."""
    (r0, h0), (r1, h1) = ORBIT_RINGS[0], ORBIT_RINGS[-1]
    radius, height = r0 + s * (r1 - r0), h0 + s * (h1 - h0)
    az = np.deg2rad(azimuth_deg)
    eye = WORKSPACE_CENTER + np.array([radius * np.cos(az), radius * np.sin(az), height])
    return look_at(name, eye, fovy=fovy)


@dataclass(frozen=True)
class Randomization:
    """The visuals of one episode: the object's sRGB and the perturbed cameras' poses."""

    object_rgb: tuple[float, float, float]
    cameras: dict[str, CameraPose]

    def record(self) -> dict:
        """Flat provenance columns (one row per episode in meta/roboview/episodes.parquet)."""
        row = {
            "object_rgb": [float(v) for v in self.object_rgb],
            "object_lab": [float(v) for v in srgb_to_lab(np.asarray(self.object_rgb))],
        }
        for name, pose in self.cameras.items():
            row[f"camera_{name}_pos"] = [float(v) for v in pose.pos]
            row[f"camera_{name}_quat"] = [float(v) for v in pose.quat]
            row[f"camera_{name}_fovy"] = float(pose.fovy)
        return row


def baseline_randomization() -> Randomization:
    """What a context-only episode shows: the baseline color and the original cameras."""
    return Randomization(
        get_color(baselines()["color"]).rgb, {name: BASE_CAMERAS[name] for name in PERTURBED_CAMERAS}
    )


def sample_randomization(episode_seed: int, factors: tuple[str, ...]) -> Randomization:
    """Draw the randomized `factors` for one episode; the others stay at baseline."""
    rng = np.random.default_rng([STREAM, episode_seed])
    base = baseline_randomization()
    rgb, cameras = base.object_rgb, base.cameras
    if "color" in factors:
        rgb = tuple(float(v) for v in rng.uniform(0.0, 1.0, size=3))
    if "camera_pose" in factors:
        s = rng.uniform(*RING_COORD_RANGE)
        azimuth = rng.uniform(*AZIMUTH_RANGE_DEG)
        fovy = rng.uniform(*FOVY_RANGE_DEG)
        cameras = {name: ring_pose(name, s, azimuth, fovy) for name in PERTURBED_CAMERAS}
    return Randomization(rgb, cameras)
