"""The second task, `push`: its scripted expert, its contexts, its collection path and its suite."""

import itertools

import numpy as np
import pandas as pd
import pytest

from roboview.tasks import load_preset, load_task, make_env
from roboview.tasks.push import PUSH_STARTS, ZONE_OFFSETS
from roboview.variation.factors import baselines, context_factors
from roboview.variation.instances import TaskInstance, episode_seed, generate_suite

pytestmark = pytest.mark.slow


def push_instance(**values):
    return TaskInstance("t", ("color",), baselines("push") | values, "base", task="push")


def test_the_push_expert_solves_every_context():
    env = make_env("push", cameras=("front",), image_size=32, lazy=True)  # the expert reads no image
    expert = load_task("push").make_expert(env)
    outcomes = []
    try:
        for start, zone, shape in itertools.product(
            PUSH_STARTS, ZONE_OFFSETS, ("cube", "cuboid", "hex_prism")
        ):
            inst = push_instance(push_start=start, zone=zone, push_shape=shape)
            # Every context once, at its repeat-0 seed.
            obs, _ = env.reset(seed=episode_seed(inst.context_id, 0), options={"instance": inst})
            expert.reset()
            for _ in range(env.max_steps):
                obs, _, success, truncated, _ = env.step(expert.select_action(obs))
                if success or truncated:
                    break
            outcomes.append(success)
            # Success means the object's center rests inside the zone.
            if success:
                assert np.all(np.abs(env.object_pose()[0][:2] - env.zone_center) < 0.05)
    finally:
        env.close()
    assert np.mean(outcomes) >= 0.95, np.mean(outcomes)


def test_push_is_not_a_free_success():
    env = make_env("push", cameras=("front",), image_size=32, lazy=True)
    try:
        obs, _ = env.reset(seed=0, options={"instance": push_instance()})
        for _ in range(20):  # holding still never succeeds: the object starts 15 cm from the zone
            obs, _, success, _, _ = env.step(np.append(obs["observation.state"][:7], 0.0))
            assert not success
        assert np.linalg.norm(env.object_pose()[0][:2] - env.zone_center) > 0.1
    finally:
        env.close()


def test_push_instances_have_their_own_contexts_and_ids():
    assert context_factors("push") == ("push_start", "zone", "push_shape", "push_instruction")
    suite = generate_suite(load_preset("extended"))
    push = [i for i in suite if i.task == "push"]
    assert len(suite) == 5101 and len(push) == 2655
    assert {i.split for i in push} == {f"push_{s}" for s in load_preset("extended").splits}
    assert len({i.context_id for i in push if i.split == "push_color"}) == 12
    # A pick_place instance and a push instance with the same visual values never share an id.
    assert not {i.instance_id for i in push} & {i.instance_id for i in suite if i.task == "pick_place"}
    with pytest.raises(ValueError, match="this env runs 'pick_place'"):
        make_env("pick_place", cameras=("front",), image_size=32).reset(options={"instance": push[0]})


def test_collect_push_demos(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    root = tmp_path / "push"
    result = collect(
        CollectConfig(
            DatasetConfig(
                repo_id="t/push",
                root=str(root),
                num_episodes=2,
                image_size=32,
                cameras=["front"],
                task="push",
            ),
            num_workers=1,
        )
    )
    assert result.episodes == 2
    dataset = LeRobotDataset("t/push", root=root)
    assert dataset.num_episodes == 2 and dataset[0]["task"].startswith(("push", "slide"))
    provenance = pd.read_parquet(root / "meta" / "roboview" / "episodes.parquet")
    assert {"push_start", "zone", "push_shape", "push_instruction"} <= set(provenance.columns)


def test_a_two_task_benchmark_builds_loads_and_evaluates(tmp_path):
    import datasets

    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.policies.types import policy_config

    bench = tmp_path / "bench"
    result = build(BuildConfig(output_dir=str(bench), preset="tiny_extended", image_size=64))
    assert result.candidates == 168 and result.accepted == 168
    # One dataset config per task: their context columns differ.
    push = datasets.load_dataset(str(bench), "push", split="push_distractors")
    assert push.num_rows == 6 and {"push_start", "zone", "distractors"} <= set(push.column_names)
    assert "initial_position" in datasets.load_dataset(str(bench), split="lighting").column_names
    out = evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(bench), "lighting,push_lighting"),
            policy_config("expert"),
            EvalConfig(n_repeats=1, num_workers=2, image_size=32),
            str(tmp_path / "eval"),
        )
    )
    rows = pd.read_parquet(tmp_path / "eval" / "episodes.parquet")
    assert out.episodes == 18 and set(rows["task"]) == {"pick_place", "push"} and rows["success"].all()
