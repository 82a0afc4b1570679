"""The seams the architecture promises: a visual factor is one module, a policy sees no instance."""

import dataclasses

import numpy as np
import pytest

from roboview.policies.base import AgentView, Episode, PolicyConfig
from roboview.policies.factory import make_policy
from roboview.policies.types import policy_config
from roboview.tasks import load_preset, make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.tasks.pick_place import PickPlaceEnv
from roboview.variation.factors import (
    Factor,
    baselines,
    factor_names,
    register_factor,
    unregister_factor,
)
from roboview.variation.instances import SuiteConfig, generate_suite

pytestmark = pytest.mark.slow

PAPER_FIRST_ID = (
    "1209193fe4df70d1"  # first instance of the `paper` preset (tests/variation/test_stable_ids.py)
)


class TableTint:
    """A throwaway visual factor's applier: bound to the table geom's rgba, written in place."""

    TINTS = {"plain": None, "blue": (0.2, 0.3, 0.8, 1.0), "green": (0.2, 0.7, 0.3, 1.0)}

    def __init__(self, scene) -> None:
        self.rgba = scene.model.geom_rgba
        self.table = scene.ids.table_geom
        self.plain = self.rgba[self.table].copy()

    def apply(self, value: str, rng: np.random.Generator) -> None:
        tint = self.TINTS[value]
        self.rgba[self.table] = self.plain if tint is None else tint


@pytest.fixture()
def table_tint():
    factor = register_factor(
        Factor(
            name="table_tint",
            kind="visual",
            values=("plain", "blue", "green"),
            baseline="plain",
            doc="table color",
            bind=TableTint,
        )
    )
    yield factor
    unregister_factor("table_tint")


def test_a_visual_factor_is_one_module_and_one_registry_line(table_tint):
    # The registry, suites, ids and env all pick it up; published ids do not move.
    assert "table_tint" in factor_names()
    assert generate_suite(load_preset("paper"))[0].instance_id == PAPER_FIRST_ID
    suite = generate_suite(
        SuiteConfig(
            preset="test",
            splits=("table_tint",),
            union_mode="dedupe",
            value_subsets=(
                ("initial_position", ("center",)),
                ("shape", ("cube",)),
                ("instruction", (baselines()["instruction"],)),
            ),
        )
    )
    assert [i.value for i in suite] == ["plain", "blue", "green"]
    assert len({i.instance_id for i in suite}) == 3 and len({i.context_id for i in suite}) == 1
    env = PickPlaceEnv(cameras=("front",), image_size=64)
    try:
        frames = {}
        for instance in [*suite, suite[0]]:
            obs, _ = env.reset(options={"instance": instance})
            frame = obs[IMAGE_KEY.format("front")]
            assert frame.std() > 5
            frames.setdefault(instance.value, []).append(frame)
        # Values render differently; switching back in place restores the baseline bit for bit.
        assert not np.array_equal(frames["plain"][0], frames["blue"][0])
        assert not np.array_equal(frames["blue"][0], frames["green"][0])
        assert np.array_equal(frames["plain"][0], frames["plain"][1])
    finally:
        env.close()


def test_records_keep_the_task_and_context_subspace():
    instance = generate_suite(load_preset("tiny"))[0]
    record = instance.to_record()
    assert record["task"] == "pick_place" and record["context_subspace"] == instance.context_subspace


class _Snoop:
    """Tries every way a sneaky policy might read the instance's color."""

    name = "snoop"
    failure_reason = ""

    def __init__(self, view):
        self.view = view
        self.seen: list = []

    def reset(self, episode):
        self.seen.append(episode)

    def select_action(self, observation):
        return np.append(observation["observation.state"][:7], 0.0).astype(np.float32)

    def close(self):
        pass


def test_a_policy_cannot_read_the_instance():
    @dataclasses.dataclass
    class SnoopConfig(PolicyConfig):
        def build(self, view):
            return _Snoop(view)

    env = make_env("pick_place", cameras=("front",), image_size=32)
    try:
        blue = dataclasses.replace(env.instance, factors={**env.instance.factor_values, "color": "blue"})
        env.reset(options={"instance": blue})
        policy = make_policy(SnoopConfig(), env)
        view = policy.view
        assert isinstance(view, AgentView) and not isinstance(view, PickPlaceEnv)
        # Its fields are the env's interface only; none is the env, its scene or the instance.
        assert {f.name for f in dataclasses.fields(AgentView)} == {
            "task",
            "cameras",
            "image_size",
            "depth",
            "fps",
            "control",
            "action_space",
            "joint_action_space",
            "observation_space",
        }
        assert not hasattr(view, "instance") and not hasattr(view, "env") and not hasattr(view, "scene")
        # The kinematic model is the scene at defaults, not the live one: the object's color is not in it.
        model = view.kinematic_model()
        assert model is not env.model
        geom = env.scene.active_geom
        assert np.allclose(env.model.geom_rgba[geom][:3], (0, 0, 1)) and not np.allclose(
            model.geom_rgba[geom][:3], (0, 0, 1)
        )
        # The episode names the instruction, seed and calibration: no factor value of the instance.
        episode = Episode.of(env, 7)
        assert {f.name for f in dataclasses.fields(Episode)} == {
            "task",
            "instruction",
            "seed",
            "cameras",
            "image_size",
        }
        assert "blue" not in repr(episode)
        assert episode.cameras["front"] == env.scene.camera_pose("front")
    finally:
        env.close()


def test_only_the_expert_is_privileged():
    assert policy_config("expert").privileged
    assert not any(policy_config(t).privileged for t in ("random", "vision"))
    env = make_env("pick_place", cameras=("front",), image_size=32)
    try:
        env.reset()
        expert = make_policy(policy_config("expert"), env)
        assert expert._expert.env is env  # the privileged expert gets the env itself, by its type
        random_policy = make_policy(policy_config("random"), env)  # a non-privileged type never holds the env
        assert not any(value is env for value in vars(random_policy).values())
        assert type(random_policy).__name__ == "RandomPolicy"
    finally:
        env.close()


def test_console_scripts_are_installed_and_answer_help():
    """Every verb's installed script answers --help with its flags: each script's file runs in this process as its
    interpreter runs it, and one runs as the program a user starts (its #! line and all)."""
    import os
    import subprocess
    import sys
    import tomllib
    from pathlib import Path

    from roboview.pipelines._console import VERBS, script_name
    from tests.helpers.docs import script_help_run

    declared = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"][
        "scripts"
    ]
    assert declared == {script_name(v): f"roboview.pipelines._console:{v}" for v in VERBS}
    bindir = Path(sys.executable).parent
    for script, flag in (
        ("roboview-evaluate", "--eval.envs_per_worker"),
        ("roboview-collect", "--dataset.task"),
        ("roboview-build-benchmark", "--preset"),
        ("roboview-report", "--results"),
        ("roboview-publish", "--repo_id"),
        ("roboview-train", "--steps"),
        ("roboview-verify", "--results"),
        ("roboview-serve-policy", "--port"),
    ):
        assert os.access(bindir / script, os.X_OK), script
        proc = script_help_run(bindir / script)
        assert proc.returncode == 0 and flag in proc.stdout, (script, proc.stderr[-500:])
    proc = subprocess.run(
        [str(bindir / "roboview-report"), "--help"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0 and "--results" in proc.stdout, proc.stderr[-500:]
