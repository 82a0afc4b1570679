"""The `vision` policy: a SimpleAgent analogue that acts from one RGB-D glance, no privileged state.

At the first observation of an episode it runs classic colour-based perception
(`roboview.policies.perception`) on one scene camera (default `front`; `--policy.camera=left_top` picks
another), then runs the task's scripted solution (`TaskEnv.plan`, what its expert runs) with the
*perceived* object position, heading and box center. It never looks again, so whatever the
camera's view of that one frame gets wrong — a yellow object taken for the box, a grey one lost in
the table, a far camera leaving a handful of pixels — is exactly what the benchmark measures.

What it reads: the rendered observation, the camera's calibration from the `Episode` (intrinsics +
extrinsics, as a real robot would have), the robot's kinematic model from its `AgentView` and its
own joint reading from ``observation.state``. Never the object pose, never the instance.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, ControlledConfig, Episode, PolicyConfig
from roboview.policies.perception import Perception, PerceptionError, perceive
from roboview.sim.cameras import ALL_CAMERAS, CameraPose
from roboview.sim.motion import MotionPlanner
from roboview.tasks import load_task
from roboview.tasks.env import DEPTH_KEY, IMAGE_KEY, STATE_KEY

log = logging.getLogger(__name__)

DEFAULT_CAMERA = "front"


@PolicyConfig.register_subclass("vision")
@dataclass
class VisionConfig(ControlledConfig):
    """Colour-based RGB-D perception of one scene camera, then the expert's motion."""

    # Scene camera the policy looks through (front, left_top, right_top or wrist).
    camera: str = DEFAULT_CAMERA

    depth = True
    plans_joints = True
    doc = "classic colour-based RGB-D perception of one camera (--policy.camera=front) + scripted motion"

    def __post_init__(self) -> None:
        if self.camera not in ALL_CAMERAS:
            raise ValueError(
                f"vision policy: unknown camera {self.camera!r}; allowed: {', '.join(ALL_CAMERAS)}"
            )
        super().__post_init__()

    def observed_cameras(self) -> tuple[str, ...]:
        return (self.camera,)

    def build(self, view: AgentView) -> VisionPolicy:
        return VisionPolicy(view, self.camera)


class VisionPolicy:
    """Perceive once, then follow the expert's min-jerk plan through the perceived poses.

    If perception fails the episode is spent holding the first observed joint positions with the
    gripper open — deterministic, harmless — and `failure_reason` says why (the evaluator records it
    as the episode's failure reason). `failure_reason` is empty whenever perception succeeded, so a
    botched grasp is reported by the evaluator's own outcome text instead.
    """

    name = "vision"

    def __init__(self, view: AgentView, camera: str = DEFAULT_CAMERA) -> None:
        if camera not in view.cameras or not view.depth:
            raise ValueError(
                f"vision policy needs RGB-D from camera {camera!r}; env renders "
                f"{view.cameras} with depth={view.depth}"
            )
        self.camera = camera
        self._motion = MotionPlanner(view.kinematic_model())
        self._calibration: CameraPose | None = None
        self._task = load_task()
        self.perception: Perception | None = None
        self.failure_reason = ""
        self._hold: np.ndarray | None = None
        self._planned = False

    def reset(self, episode: Episode) -> None:
        # Perception waits for the first observation; the episode gives the camera's calibration.
        self._calibration = episode.cameras[self.camera]
        self._task = load_task(episode.task)
        self.perception = None
        self.failure_reason = ""
        self._hold = None
        self._planned = False

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        if not self._planned:
            self._plan_from(observation)
        if self._hold is not None:
            return self._hold
        return self._motion.next_action()

    def _plan_from(self, observation: dict[str, np.ndarray]) -> None:
        self._planned = True
        arm_q = observation[STATE_KEY][:7].astype(np.float64)
        try:
            self.perception = perceive(
                observation[IMAGE_KEY.format(self.camera)],
                observation[DEPTH_KEY.format(self.camera)],
                self._calibration,
                target=self._task.target,
            )
        except PerceptionError as err:
            self.failure_reason = err.reason
            self._hold = np.append(arm_q, 0.0).astype(np.float32)
            log.debug("vision policy: %s; holding still", err.reason)
            return
        p = self.perception
        # The task's own scripted solution, as its expert runs it, through the perceived poses.
        self._task.solve(self._motion, p.object_pos, p.object_yaw, p.symmetry, p.box_xy, arm_q)

    def close(self) -> None:
        pass
