"""What a task is, and the live registries of tasks and of suite presets.

A task is what a policy is asked to do in the shared world (`roboview.sim`). A `Task` names its
gymnasium id and env class, its privileged scripted expert, and the small context subsets the
`tiny` presets use; everything else a task declares lives on its env class (`roboview.tasks.env.
TaskEnv`): what it adds to the scene (`add_target`), its target (`target`, `target_geoms`,
`target_xy`), how its context factors place the scene (`place_context`), its success test
(`is_success`) and its scripted solution (`plan`). Its context factors are registered with
`task=<name>` in the factor registry (`roboview.variation.factors.register_factor`). Envs are
made through gymnasium (`make_env`), never by naming a class.

Both registries are filled by the worlds' wings (their task modules, with their presets) and discovered when read
(roboview.core.registry): they list RoboView's own tasks first, then LIBERO's, Meta-World's and LIBERO-plus's, as
RoboView's `roboview.tasks` entry points order them, and then another package's. A preset is listed with its first
task.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from roboview.core.registry import Registry
from roboview.sim.motion import MotionPlanner
from roboview.tasks.decomposition import Decomposition
from roboview.tasks.env import ASSUMED_REACH_M, DEFAULT_MAX_STEPS, action_names, state_names
from roboview.variation.factors import DEFAULT_TASK, context_factors

if TYPE_CHECKING:
    from roboview.variation.instances import SuiteConfig, TaskInstance


def resolve(target: str) -> Any:
    """The object a "module:attr" string names."""
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


@dataclass(frozen=True)
class Task:
    name: str
    # Gymnasium id, registered with `max_episode_steps`.
    gym_id: str
    # "module:Class" of the gymnasium env, a `TaskEnv` (its scene additions, target, reset and success test).
    env: str
    # One line: when an episode of this task succeeds.
    success: str
    # What an episode that runs out of steps is recorded as ("… within N steps").
    timeout_reason: str
    # "module:Class" of the privileged scripted expert: `Expert(env)`, `.reset()`, `.select_action(obs)`.
    # The default plans the env's own `plan` from the object's true pose.
    expert: str = "roboview.tasks.expert:ScriptedExpert"
    # Context values of the small presets (`tiny`, `tiny_extended`), as (factor, values) pairs.
    small_contexts: tuple[tuple[str, tuple[str, ...]], ...] = ()
    max_episode_steps: int = DEFAULT_MAX_STEPS
    # Whether an episode's step budget depends on its context (LIBERO: its suite's); the env then sets it per
    # reset, and an evaluation without --eval.max_steps records none.
    steps_per_context: bool = False
    # What the episode seed randomizes in this task's scenes ("": nothing, so a repeat is a copy unless
    # `repeat_factor` makes it another episode). roboview.tasks.repetition reads both.
    seed_randomizes: str = "the object's start: up to 1 cm of position jitter and ±20° of heading"
    # The context factor a repeat advances where the seed is not the episode's randomness (LIBERO's `init_state`).
    repeat_factor: str = ""
    # The context factor whose value names the compiled world an instance runs in (LIBERO's `libero_task`: one
    # model per LIBERO task); builds and evaluations hand a worker one world's instances together. "": one world.
    world_factor: str = ""
    # Analyses particular to this task, as designs (data), run on each policy's episodes of it beside the splits'
    # statistics: a `Decomposition` takes one factor apart into its sub-factors (roboview.tasks.decomposition;
    # metrics.json's `analyses.<key>` and its report section). LIBERO-plus's camera decomposition is one.
    analyses: tuple[Decomposition, ...] = ()

    def world_of(self, instance: TaskInstance) -> str:
        """The world `instance` runs in: the task's name, and its `world_factor`'s value where it has one."""
        return f"{self.name}/{instance.get(self.world_factor)}" if self.world_factor else self.name

    def default_steps(self) -> int | None:
        """The step budget of an evaluation that sets none: the task's, or None when each context has its own."""
        return None if self.steps_per_context else self.max_episode_steps

    def context_factors(self) -> tuple[str, ...]:
        return context_factors(self.name)

    def timeout_failure(self, max_steps: int) -> str:
        """The failure reason of an episode that ran out of steps: "<timeout_reason> within N steps"."""
        return f"{self.timeout_reason} within {max_steps} steps"

    def env_class(self) -> type:
        return resolve(self.env)

    @property
    def target(self) -> str | None:
        """What besides the object a policy must find: "box", "zone", … or None."""
        return self.env_class().target

    def solve(
        self,
        planner: MotionPlanner,
        obj_pos: np.ndarray,
        obj_yaw: float,
        symmetry: float,
        target_xy: np.ndarray | None,
        arm_qpos: np.ndarray,
    ) -> None:
        """The task's scripted solution (its env's `plan`) from perceived poses, as a non-privileged agent
        runs it: the object's extent is assumed (`ASSUMED_REACH_M`), the pinch point computed from the joints."""
        self.env_class().plan(planner, obj_pos, obj_yaw, symmetry, ASSUMED_REACH_M, target_xy, arm_qpos)

    def make_expert(self, env: gym.Env) -> Any:
        return resolve(self.expert)(env)


def task_module(task: Task) -> str:
    """The module a task comes from: its env's."""
    return task.env.partition(":")[0]


TASKS: Registry[Task] = Registry("task", origin=task_module)


def register_task(task: Task) -> Task:
    """Add `task` to the registry and gymnasium's (a name can be registered once)."""
    if task.name in TASKS.registered:
        raise ValueError(f"task {task.name!r} is already registered")
    if not context_factors(task.name):
        raise ValueError(
            f"task {task.name!r} has no context factors: register them first with "
            f"register_factor(Factor(..., kind='context', task={task.name!r}))"
        )
    TASKS.add(task.name, task)
    if task.gym_id not in gym.registry:
        gym.register(id=task.gym_id, entry_point=task.env, max_episode_steps=task.max_episode_steps)
    return task


def preset_module(cfg: SuiteConfig) -> str:
    """The module a preset is listed with: its first task's."""
    task = TASKS.registered.get(cfg.tasks[0])
    return "" if task is None else task_module(task)


PRESETS: Registry[SuiteConfig] = Registry("preset", origin=preset_module)


def register_preset(cfg: SuiteConfig) -> SuiteConfig:
    """Add a suite preset under `cfg.preset` (a name can be registered once)."""
    return PRESETS.add(cfg.preset, cfg)


def load_preset(name: str) -> SuiteConfig:
    """Return the registered suite preset `name`; unknown names raise listing the valid ones."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(PRESETS)}") from None


def analysis_designs() -> dict[str, Decomposition]:
    """Every registered task's analyses (`Task.analyses`), by their key."""
    return {design.key: design for task in TASKS.values() for design in task.analyses}


def load_task(name: str = DEFAULT_TASK) -> Task:
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; allowed: {', '.join(TASKS)}") from None


def camera_names() -> tuple[str, ...]:
    """Every camera name some registered task's env renders (a checkpoint that wants another is refused at once;
    whether the benchmark's own tasks render it is checked when the run is planned)."""
    return tuple(dict.fromkeys(c for task in TASKS.values() for c in task.env_class().world.cameras))


def feature_dims() -> list[tuple[str, int, int]]:
    """(control, state width, action width) of every registered task's env in every control it takes: the
    `observation.state` and `action` a LeRobot dataset of that env holds."""
    out = []
    for task in TASKS.values():
        env_class = task.env_class()
        for control in env_class.world.controls:
            declared = env_class.feature_names(control)
            if declared is None:
                declared = (state_names(control), action_names(control))
            widths = [len(next(iter(n.values())) if isinstance(n, dict) else n) for n in declared]
            out.append((control, *widths))
    return list(dict.fromkeys(out))


def control_of_action_names(names: list[str]) -> str | None:
    """The control whose action a dataset with these `action` names recorded, in whichever registered world names
    its actions so (LeRobot-format LIBERO datasets: LIBERO's OSC_POSE deltas, `ee_delta`); None: no world's."""
    for task in TASKS.values():
        env_class = task.env_class()
        for control in env_class.world.controls:
            declared = env_class.feature_names(control)
            action = action_names(control) if declared is None else declared[1]
            if list(action["motors"] if isinstance(action, dict) else action) == list(names):
                return control
    return None


def make_env(task: str = DEFAULT_TASK, **kwargs: Any) -> gym.Env:
    """The task's env through `gym.make` (unwrapped: RoboView's loops read its scene and step counter)."""
    return gym.make(load_task(task).gym_id, disable_env_checker=True, **kwargs).unwrapped
