"""The privileged scripted expert solves every context at baseline visuals, in every control mode."""

import itertools

import numpy as np
import pytest

from roboview.tasks import ScriptedExpert
from roboview.tasks.pick_place import PickPlaceEnv
from roboview.variation.factors import FACTORS, baselines
from roboview.variation.instances import TaskInstance

pytestmark = [
    pytest.mark.slow,
    pytest.mark.schedule_first,  # three sweeps of 48 episodes, ≈ 50 s: never the run's last file (tests/conftest.py, schedule)
]


def sweep(env: PickPlaceEnv) -> tuple[list[bool], list[int]]:
    """The expert over all 48 contexts (a distinct jitter per episode): outcomes and steps."""
    expert = ScriptedExpert(env)
    contexts = list(
        itertools.product(
            FACTORS["initial_position"].values, FACTORS["shape"].values, FACTORS["instruction"].values
        )
    )
    assert len(contexts) == 48
    outcomes, steps = [], []
    for i, (position, shape, instruction) in enumerate(contexts):
        values = dict(baselines(), initial_position=position, shape=shape, instruction=instruction)
        instance = TaskInstance("train", ("initial_position", "shape"), values, "cartesian")
        obs, _ = env.reset(seed=1000 + i, options={"instance": instance})
        expert.reset()
        for _ in range(env.max_steps):
            obs, _, terminated, truncated, _ = env.step(expert.select_action(obs))
            if terminated or truncated:
                break
        outcomes.append(terminated)
        steps.append(env.steps)
        if terminated:
            pos, _ = env.object_pose()
            assert env.is_success() and pos[2] < 0.07  # really inside the box, not above it
    return outcomes, steps


def test_expert_success_rate_over_all_contexts():
    env = PickPlaceEnv(cameras=("front",), image_size=32, lazy=True)  # the expert reads no image
    outcomes, steps = sweep(env)
    env.close()
    assert np.mean(outcomes) >= 0.95, f"expert success {np.mean(outcomes):.1%} over {len(outcomes)} episodes"
    assert max(steps) <= 100


@pytest.mark.parametrize("control", ["ee_delta", "ee_abs"])
def test_expert_succeeds_through_end_effector_control(control):
    """Its joint plan as EE actions (ee_abs: the targets' pose; ee_delta: their offset from the EE state)."""
    env = PickPlaceEnv(cameras=("front",), image_size=32, lazy=True, control=control)
    outcomes, steps = sweep(env)
    env.close()
    assert np.mean(outcomes) >= 0.98, f"{control}: expert success {np.mean(outcomes):.1%} over 48 episodes"
    assert max(steps) <= 100
