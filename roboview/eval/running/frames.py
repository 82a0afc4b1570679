"""Frames that cannot be right: the evaluator's check of every camera image a policy is handed, in every world.

A MuJoCo renderer that does not make its own GL context current before it draws (gymnasium's, behind Meta-World's
scenes, until `MetaWorldScene.render` made it so) draws in whatever context is current. Once another renderer is made
and used in the same process (a `mujoco.Renderer` on another model), nothing raises, and the env's frames come back
all black, or as one frame frozen while the scene moves on. Every world here now makes its own context current; the
check catches what another world, renderer or driver still gets wrong. A policy shown such frames fails through no fault of its own, so after every policy call
`FrameCheck.check` looks at the frames the observation holds — the cameras the policy read (a lazy observation's
unread cameras are never rendered for the check) and those the evaluator rendered for a video — and raises
`RenderError` (the episode ends as `infra_error`, counted in no rate, re-run later) when

- a frame is **constant**: every pixel the same color. A lit scene never renders so; a dark one still has edges
  and shading, pixels that differ, and passes;
- the **first frames of an episode are bit-identical to the last ones the env showed before its reset, though the
  scene moved** between the two: the robot's state (`env.state()`) by more than `MOVED` in some entry (rad, m or
  gripper closure), which every camera shows or rides on, or — for a scene camera the fairness gate judges, where
  the object is in view — the object's position by more than `MOVED` m. Every camera compared must be identical.
  An episode that starts from the state the last frame was taken in (the same context and repeat run again, a
  LIBERO init state whose seed changes nothing) may show that very frame: it is not flagged. The episode that starts
  on a frozen frame is not told apart (its first frame is new to the env); the next reset gives it away. A frame
  drawn with another scene's meshes and textures is neither, and passes.

The cost is one pass over the frame's bytes (≈ 10 µs at 224², docs/evaluation.md), and the states read only when a
frame was read; an observation whose cameras no one read costs nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.core.errors import RenderError
from roboview.sim.observation import LazyObservation

IMAGE_PREFIX = "observation.images."
# How far the scene must have moved (an entry of the robot's state, in rad, m or gripper closure; the object, in m)
# for a frame that did not change to be impossible: ≥ 2 px at 224² from a metre away, far above physics' noise.
MOVED = 0.01
CAUSE = "another renderer in this process may have taken the GL context"


def observed_frames(obs) -> dict[str, np.ndarray]:
    """camera → image of what `obs` holds now, rendering nothing: a lazy observation's rendered cameras, a plain
    dict's every camera."""
    if isinstance(obs, LazyObservation):
        keys = [k for k in obs.rendered() if k.startswith(IMAGE_PREFIX)]
        return {k[len(IMAGE_PREFIX) :]: dict.__getitem__(obs, k) for k in keys}
    return {k[len(IMAGE_PREFIX) :]: v for k, v in obs.items() if k.startswith(IMAGE_PREFIX)}


def constant_color(frame: np.ndarray) -> tuple[int, ...] | None:
    """The one color every pixel of `frame` (H×W×C or H×W) holds, or None when two pixels differ."""
    channels = frame.shape[-1] if frame.ndim == 3 else 1
    data = np.ascontiguousarray(frame).reshape(-1)
    # Every pixel equals the next one: the byte stream equals itself shifted by one pixel.
    if data.size > channels and not np.array_equal(data[channels:], data[:-channels]):
        return None
    return tuple(int(v) for v in data[:channels])


def describe(color: tuple[int, ...]) -> str:
    return f"all {color[0]}" if len(set(color)) == 1 else f"every pixel {color}"


@dataclass(frozen=True)
class SceneState:
    """What a frame shows of the simulation: the robot's state and the object's position."""

    robot: np.ndarray
    object: np.ndarray

    @classmethod
    def of(cls, env) -> SceneState:
        return cls(np.asarray(env.state(), float).ravel(), np.asarray(env.object_pose()[0], float).ravel())

    @staticmethod
    def _change(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.max(np.abs(a - b), initial=0.0)) if a.shape == b.shape else np.inf

    def moved(self, other: SceneState, object_in_view: bool) -> str:
        """How the scene moved from `other` to here, as a camera must show it ("" when it need not have)."""
        robot, obj = self._change(self.robot, other.robot), self._change(self.object, other.object)
        parts = [f"robot state by {robot:.3g}"] if robot > MOVED else []
        if object_in_view and obj > MOVED:
            parts.append(f"object by {obj:.3g} m")
        return ", ".join(parts)


class FrameCheck:
    """One env's check: constant frames always, and the first frames of an episode against the last ones before
    its reset (`new_episode()` marks the reset)."""

    def __init__(self, env) -> None:
        self.env = env
        world = env.world
        scene = {world.cameras[c] for c in world.judged_cameras if c not in world.wrist_cameras}
        # The env's cameras (aliases too) in which the gate requires the object visible.
        self.object_cameras = {c for c in world.cameras if world.cameras[c] in scene}
        # camera → (its last frame that passed, the scene state it was taken in)
        self.last: dict[str, tuple[np.ndarray, SceneState]] = {}
        self._first = False

    def new_episode(self) -> None:
        self._first = True

    def check(self, obs) -> None:
        """Raise `RenderError` when a frame `obs` holds cannot be right (module docstring); remember the frames."""
        frames = observed_frames(obs)
        if not frames:
            return
        for camera, frame in frames.items():
            color = constant_color(frame)
            if color is not None:
                raise RenderError(
                    f"render: camera {camera} returned a constant frame ({describe(color)}) — {CAUSE}"
                )
        state = SceneState.of(self.env)
        if self._first:
            self._first = False
            self._check_reset(frames, state)
        for camera, frame in frames.items():
            self.last[camera] = (frame, state)

    def _check_reset(self, frames: dict[str, np.ndarray], state: SceneState) -> None:
        before = {c: self.last[c] for c in frames if c in self.last}
        if not before or not all(np.array_equal(frames[c], frame) for c, (frame, _) in before.items()):
            return
        for camera, (_, then) in before.items():
            how = state.moved(then, camera in self.object_cameras)
            if how:
                raise RenderError(
                    f"render: camera {camera} returned the last frame it showed before the reset though the "
                    f"scene moved ({how}) — {CAUSE}"
                )
