"""The task registry: what a task adds to the scene, how it is made, solved and judged.

A task is the thing a policy is asked to do (the paper has one: put the small object into the
yellow box). Each `Task` names its gymnasium id and env class (whose scene additions — the receiver
box — and success test live in that class), its privileged scripted expert, the targets the
fairness gate must see in every observed camera, and its context factors (registered in
`roboview_data.variation.factors` with `task=<name>`: object positions, shapes, instructions).
Envs are made through gymnasium (`make_env`), never by naming a class.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

DEFAULT_TASK = "pick_place"
DEFAULT_MAX_STEPS = 120


def _resolve(target: str) -> Any:
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


@dataclass(frozen=True)
class Task:
    name: str
    # Gymnasium id, registered with `max_episode_steps`.
    gym_id: str
    # "module:Class" of the gymnasium env (its scene additions, reset and success test).
    env: str
    # "module:Class" of the privileged scripted expert: `Expert(env)`, `.reset()`, `.select_action(obs)`.
    expert: str
    # One line: when an episode of this task succeeds.
    success: str
    # What the fairness gate requires to be visible in every observed camera.
    fairness_targets: tuple[str, ...] = ("object", "box")
    # What an episode that runs out of steps is recorded as ("… within N steps").
    timeout_reason: str = "object not released inside the box"
    max_episode_steps: int = DEFAULT_MAX_STEPS

    def context_factors(self) -> tuple[str, ...]:
        from roboview_data.variation.factors import context_factors

        return context_factors(self.name)

    def make_expert(self, env: gym.Env) -> Any:
        return _resolve(self.expert)(env)


TASKS: dict[str, Task] = {}


def register_task(task: Task) -> Task:
    if task.name in TASKS:
        raise ValueError(f"task {task.name!r} is already registered")
    TASKS[task.name] = task
    if task.gym_id not in gym.registry:
        gym.register(id=task.gym_id, entry_point=task.env, max_episode_steps=task.max_episode_steps)
    return task


def load_task(name: str = DEFAULT_TASK) -> Task:
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; allowed: {', '.join(TASKS)}") from None


def make_env(task: str = DEFAULT_TASK, **kwargs: Any) -> gym.Env:
    """The task's env through `gym.make` (unwrapped: RoboView's loops read its scene and step counter)."""
    return gym.make(load_task(task).gym_id, disable_env_checker=True, **kwargs).unwrapped


register_task(Task(
    name="pick_place",
    gym_id="RoboView/PickPlace-v0",
    env="roboview_data.sim.env:PickPlaceEnv",
    expert="roboview_data.sim.expert:ScriptedExpert",
    success=("the object's center lies inside the box below its rim, moves slower than 5 cm/s, touches no "
             "part of the robot, and the gripper is open"),
))
register_task(Task(
    name="push",
    gym_id="RoboView/Push-v0",
    env="roboview_data.sim.push:PushEnv",
    expert="roboview_data.sim.push:PushExpert",
    success="the object's center lies inside the marked zone, it moves slower than 5 cm/s and touches no part of the robot",
    fairness_targets=("object", "zone"),
    timeout_reason="object not at rest inside the zone",
))
