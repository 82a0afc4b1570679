"""Built-in policy types `expert` (privileged upper bound) and `random` (floor): configs and policies.

The vision heuristic and the LeRobot checkpoint adapter live in their own modules, each registering
its own config the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, ControlledConfig, Episode, PolicyConfig
from roboview.tasks import load_task
from roboview.tasks.env import TaskEnv


class ExpertPolicy:
    """The task's scripted expert with privileged state; its Bias Coefficient should be ≈ 0."""

    name = "expert"
    failure_reason = ""

    def __init__(self, env: TaskEnv) -> None:
        self._expert = load_task(env.instance.task).make_expert(env)

    def reset(self, episode: Episode) -> None:
        self._expert.reset()

    def select_action(self, observation: dict) -> np.ndarray:
        return self._expert.select_action(observation)

    def close(self) -> None:
        pass


class RandomPolicy:
    """Uniform random joint targets near the current pose and a random gripper: the floor."""

    name = "random"
    failure_reason = ""

    def __init__(self, view: AgentView, step_rad: float = 0.15) -> None:
        # Joint targets, whatever the control (an EE control gets the EE actions reaching them).
        joint = view.joint_action_space
        self.action_space = joint if joint is not None else view.action_space
        self.step_rad = step_rad
        self._rng = np.random.default_rng(0)

    def reset(self, episode: Episode) -> None:
        # Seeded by the episode seed: repeats differ, reruns agree, values of one context share draws.
        self._rng = np.random.default_rng(episode.seed)

    def select_action(self, observation: dict) -> np.ndarray:
        q = observation["observation.state"][:7]
        target = q + self._rng.uniform(-self.step_rad, self.step_rad, size=7)
        low, high = self.action_space.low, self.action_space.high
        action = np.append(target, self._rng.uniform(0.0, 1.0)).astype(np.float32)
        return np.clip(action, low, high)

    def close(self) -> None:
        pass


@PolicyConfig.register_subclass("expert")
@dataclass
class ExpertConfig(ControlledConfig):
    """The scripted expert, reading ground-truth object and box poses from the simulator."""

    doc = "privileged scripted expert (upper bound)"
    privileged = True

    def build(self, env: TaskEnv) -> ExpertPolicy:
        return ExpertPolicy(env)


@PolicyConfig.register_subclass("random")
@dataclass
class RandomConfig(ControlledConfig):
    """Random joint targets around the current pose: the floor (in an EE control, the EE actions reaching them)."""

    doc = "random joint targets around the current pose (floor)"
    plans_joints = True

    def build(self, view: AgentView) -> RandomPolicy:
        return RandomPolicy(view)
