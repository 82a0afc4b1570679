"""The privileged scripted expert solves every context at baseline visuals."""

import itertools

import numpy as np

from roboview_data.tasks import ScriptedExpert
from roboview_data.tasks.pick_place import PickPlaceEnv
from roboview_data.variation.factors import FACTORS, baselines
from roboview_data.variation.instances import TaskInstance


def test_expert_success_rate_over_all_contexts():
    env = PickPlaceEnv(cameras=("front",), image_size=32, lazy=True)  # the expert reads no image
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
        obs, _ = env.reset(seed=1000 + i, options={"instance": instance})  # a distinct jitter per episode
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
    env.close()
    assert np.mean(outcomes) >= 0.95, f"expert success {np.mean(outcomes):.1%} over {len(outcomes)} episodes"
    assert max(steps) <= 100
