"""`vlm_simple`: the paper's SimpleAgent (after BadRobot) — the VLM's own perception, no grounding module.

The VLM sees the scene camera and the instruction and returns the object's and the target's image
points as JSON. A heuristic action policy back-projects them with the depth image and the camera's
calibration, reads the object's footprint from depth around the point (its heading, so the fingers
close across it), and runs the expert's grasp-and-place motion through those points. Whatever the
VLM gets wrong about where things are is exactly what the benchmark measures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, Episode, PolicyConfig
from roboview.policies.vlm.client import VLMClient
from roboview.policies.vlm.common import VLMConfig, check_point, object_from_point, world_point
from roboview.policies.vlm.prompts import SIMPLE_POINTS
from roboview.sim.motion import MotionPlanner
from roboview.tasks import load_task
from roboview.tasks.env import DEPTH_KEY, IMAGE_KEY, STATE_KEY


@PolicyConfig.register_subclass("vlm_simple")
@dataclass
class SimpleAgentConfig(VLMConfig):
    doc = (
        "SimpleAgent: a VLM names image points, depth + calibration turn them into a grasp "
        "(--policy.endpoint.base_url/model)"
    )

    def build(self, view: AgentView) -> SimpleAgent:
        return SimpleAgent(view, self)


class SimpleAgent:
    name = "vlm_simple"

    def __init__(self, view: AgentView, config: SimpleAgentConfig) -> None:
        self.camera = config.camera
        self.client = VLMClient(config.endpoint)
        self.planner = MotionPlanner(view.kinematic_model())
        self.failure_reason = ""
        self._episode: Episode | None = None
        self._hold: np.ndarray | None = None
        self._planned = False
        self._answer: dict = {}

    def reset(self, episode: Episode) -> None:
        self._episode = episode
        self.failure_reason = ""
        self._hold = None
        self._planned = False
        self._answer = {}

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        if not self._planned:
            self._plan(observation)
            self._planned = True  # only once the plan exists: a transient error re-asks on the retry
        return self._hold if self._hold is not None else self.planner.next_action()

    def _plan(self, observation: dict[str, np.ndarray]) -> None:
        rgb = observation[IMAGE_KEY.format(self.camera)]
        depth = observation[DEPTH_KEY.format(self.camera)]
        arm_q = observation[STATE_KEY][:7].astype(np.float64)
        h, w = rgb.shape[:2]
        episode = self._episode

        def check(answer):
            if not isinstance(answer, dict):
                raise ValueError(
                    f"expected a JSON object with object_point and target_point, got {type(answer).__name__}"
                )
            return (
                check_point(answer.get("object_point"), "object_point", w, h),
                check_point(answer.get("target_point"), "target_point", w, h),
            )

        prompt = SIMPLE_POINTS.format(width=w, height=h, instruction=episode.instruction)
        obj_px, target_px = self.client.ask_json(prompt, [rgb], check)
        self._answer = {
            "vlm_object_point": list(obj_px) if obj_px else None,
            "vlm_target_point": list(target_px) if target_px else None,
        }
        calibration = episode.cameras[self.camera]
        grasp = object_from_point(obj_px, depth, calibration) if obj_px else None
        if obj_px is None or target_px is None or grasp is None:
            self.failure_reason = (
                "VLM: no object point"
                if obj_px is None
                else "VLM: no target point"
                if target_px is None
                else "VLM point hits no graspable solid"
            )
            self._hold = np.append(arm_q, 0.0).astype(np.float32)
            return
        center, yaw, symmetry = grasp
        box_xy = world_point(target_px, depth, calibration)[:2]
        # The task's own scripted solution through the points the VLM gave.
        load_task(episode.task).solve(self.planner, center, yaw, symmetry, box_xy, arm_q)

    def episode_record(self) -> dict:
        """Columns this agent adds to the episode row: its VLM usage and the points it was given."""
        return {**self.client.take_stats(), **self._answer}

    def close(self) -> None:
        pass
