"""Repetitions that are distinct episodes: what repeat r of an instance runs, in each world.

An episode is a function of (instance, repeat). Its seed is `episode_seed(context_id, repeat)`, shared by every value
of the context, so two episodes of one (context, repeat) differ only in the factor under study. Whether repeat r is
a *new* episode depends on what the world's seed randomizes, which every task declares (`Task.seed_randomizes`):

- RoboView's scenes: the seed jitters the object's start and heading: repetitions are distinct episodes.
- LIBERO's scenes: objects start at one of the task's 50 fixed init states whatever the seed, which re-draws only
  fixture placement (in some scenes nothing). LIBERO's unit of randomness is the init state, so the task declares
  `repeat_factor = "init_state"` and repeat r runs another init state: the context's own init state s plus r·K,
  where K is the number of init states the benchmark's contexts hold per task (1 in the `libero` preset: repeat r
  runs init state r, as LeRobot's `lerobot-eval --env.type=libero` runs episode r of a task; 10 in `libero_small`,
  whose contexts are init states 0–9: repeat 1 runs 10–19). Every value of a (context, repeat) runs the same init
  state with the same seed, so the pairing stays exact.

A run that cannot give distinct episodes (more repeats than the task has init states, or a world whose seed
randomizes nothing and that names no repeat factor) is refused before any episode (`check_repeats`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from roboview.variation.factors import load_factor
from roboview.variation.instances import TaskInstance

# The episode-row column naming what a repetition varied besides the seed ("init_state=12"); absent where the
# seed is the whole of the episode's randomness.
UNIT_COLUMN = "episode_unit"


@dataclass(frozen=True)
class Repetition:
    """How repeat r of an instance of one task becomes a distinct episode."""

    # The context factor a repeat advances ("": the seed alone makes repeats distinct).
    factor: str = ""
    # How many values of `factor` the benchmark's contexts hold per task: repeat r adds r·stride.
    stride: int = 1

    def value(self, base: str, repeat: int) -> str:
        """The factor's value repeat `repeat` of a context whose own value is `base` runs."""
        return str(int(base) + repeat * self.stride)

    def instance(self, instance: TaskInstance, repeat: int) -> TaskInstance:
        """The instance repeat `repeat` runs: `instance` itself, or with its repeat factor advanced (its id and
        context stay the instance's: the row is recorded under them)."""
        if not self.factor or repeat == 0:
            return instance
        values = dict(instance.factors) | {self.factor: self.value(instance.get(self.factor), repeat)}
        return replace(instance, factors=tuple(values.items()))

    def unit(self, instance: TaskInstance, repeat: int) -> str:
        """The `episode_unit` column of repeat `repeat` ("" where the seed is the unit)."""
        if not self.factor:
            return ""
        return f"{self.factor}={self.value(instance.get(self.factor), repeat)}"

    def describe(self) -> str:
        if not self.factor:
            return "repeat r reruns the instance with episode seed r (the seed randomizes the episode)"
        return f"repeat r runs {self.factor} s + r·{self.stride} (s: the context's own {self.factor})"


SEED_ONLY = Repetition()


def repetition_of(task: str, suite: dict[str, Any] | None) -> Repetition:
    """The repetition rule of `task`'s instances in a benchmark built from `suite` (the manifest's suite record)."""
    from roboview.tasks import load_task

    factor = load_task(task).repeat_factor
    if not factor:
        return SEED_ONLY
    held = ((suite or {}).get("value_subsets") or {}).get(factor)
    return Repetition(factor, len(held) if held else len(load_factor(factor).values))


def check_repeats(episodes: list[tuple[TaskInstance, Repetition, int]]) -> dict[str, Repetition]:
    """ValueError, in one line, unless the (instance, rule, repeats) triples run distinct episodes: every advanced
    value exists, no two contexts run the same one, and a world whose seed randomizes nothing is not repeated.
    Returns the rule of each task whose repeats advance a factor (what run.json records)."""
    from roboview.tasks import load_task

    taken: dict[tuple, tuple[str, int]] = {}
    rules: dict[str, Repetition] = {}
    for instance, rule, repeats in episodes:
        if rule.factor:
            rules[instance.task] = rule
        task = load_task(instance.task)
        if repeats > 1 and not rule.factor and not task.seed_randomizes:
            raise ValueError(
                f"{repeats} repeats of the {task.name!r} task would be copies: its episode seed randomizes nothing "
                "and it names no repeat factor; run --eval.n_repeats=1"
            )
        if not rule.factor or repeats <= 1:
            continue
        factor = load_factor(rule.factor)
        base = instance.get(rule.factor)
        last = rule.value(base, repeats - 1)
        if last not in factor.values:
            most = (len(factor.values) - int(base) - 1) // rule.stride + 1
            raise ValueError(
                f"{repeats} repeats of {instance.instance_id} need {rule.factor} {last}, and a {task.name} task has "
                f"{len(factor.values)} ({rule.describe()}; this benchmark's contexts hold {rule.stride} per task): "
                f"at most {most} repeats"
            )
        context = tuple((k, v) for k, v in instance.context.items() if k != rule.factor)
        for r in range(repeats):
            key = (instance.task, instance.context_subspace, context, rule.value(base, r))
            if taken.setdefault(key, (base, r)) != (base, r):
                other = taken[key]
                raise ValueError(
                    f"repeat {r} of the context with {rule.factor} {base} and repeat {other[1]} of the one with "
                    f"{other[0]} would both run {rule.factor} {key[-1]} ({rule.describe()}): the same episode "
                    "twice; run fewer repeats or build contexts with consecutive values from 0"
                )
    return rules
