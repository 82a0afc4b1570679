"""Built-in policy types `expert` (privileged upper bound) and `random` (floor): configs and policies.

The vision heuristic and the LeRobot checkpoint adapter live in their own modules, each registering
its own config the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from policies.base import PolicyConfig
from roboview_data.sim.env import PickPlaceEnv
from roboview_data.sim.expert import ScriptedExpert
from roboview_data.variation.instances import TaskInstance


class ExpertPolicy:
    """The scripted expert with privileged state; its Bias Coefficient should be ≈ 0."""

    name = "expert"

    def __init__(self, env: PickPlaceEnv) -> None:
        self._expert = ScriptedExpert(env)

    def reset(self, instance: TaskInstance) -> None:
        self._expert.reset()

    def select_action(self, observation: dict) -> np.ndarray:
        return self._expert.select_action(observation)


class RandomPolicy:
    """Uniform random joint targets near the current pose and a random gripper: the floor."""

    name = "random"

    def __init__(self, env: PickPlaceEnv, step_rad: float = 0.15) -> None:
        self.env = env
        self.step_rad = step_rad
        self._rng = np.random.default_rng(0)

    def reset(self, instance: TaskInstance) -> None:
        # Seeded from the episode's own generator so repeats differ and reruns agree.
        self._rng = np.random.default_rng(self.env.np_random.integers(2**63))

    def select_action(self, observation: dict) -> np.ndarray:
        q = observation["observation.state"][:7]
        target = q + self._rng.uniform(-self.step_rad, self.step_rad, size=7)
        low, high = self.env.action_space.low, self.env.action_space.high
        action = np.append(target, self._rng.uniform(0.0, 1.0)).astype(np.float32)
        return np.clip(action, low, high)


@PolicyConfig.register_subclass("expert")
@dataclass
class ExpertConfig(PolicyConfig):
    """The scripted expert, reading ground-truth object and box poses from the simulator."""

    doc = "privileged scripted expert (upper bound)"

    def build(self, env: PickPlaceEnv) -> ExpertPolicy:
        return ExpertPolicy(env)


@PolicyConfig.register_subclass("random")
@dataclass
class RandomConfig(PolicyConfig):
    """Random joint targets around the current pose: the floor."""

    doc = "random joint targets around the current pose (floor)"

    def build(self, env: PickPlaceEnv) -> RandomPolicy:
        return RandomPolicy(env)
