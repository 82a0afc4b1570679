"""A policy that parts at a known step, for the pair-replay tests: it holds the arm where it is (the same action in
both episodes of a pair, whatever the cameras show) until step `part_at`, and from then on nudges its first joint by
the front camera's mean red level, so two values of the object's color give different actions from that step exactly.
Registered as `--policy.type=parting_for_tests` when this module is imported (the evaluation's workers import it
with the config they are sent)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.policies.base import ControlledConfig, PolicyConfig

TYPE = "parting_for_tests"


class PartingPolicy:
    name = TYPE
    failure_reason = ""

    def __init__(self, part_at: int) -> None:
        self.part_at, self.step = part_at, 0

    def reset(self, episode) -> None:
        self.step = 0

    def select_action(self, observation: dict) -> np.ndarray:
        action = np.append(observation["observation.state"][:7], 0.0).astype(np.float32)
        if self.step >= self.part_at:
            action[0] += 0.2 * float(observation["observation.images.front"][..., 0].mean()) / 255
        self.step += 1
        return action

    def close(self) -> None:
        pass


@PolicyConfig.register_subclass(TYPE)
@dataclass
class PartingConfig(ControlledConfig):
    """Holds still until `part_at`, then acts on the front camera's mean red (tests only)."""

    part_at: int = 5
    doc = "test policy that parts at a known step"
    plans_joints = True

    def build(self, view) -> PartingPolicy:
        return PartingPolicy(self.part_at)
