"""The `metaworld` world (roboview.metaworld): Meta-World's tasks as RoboView contexts. At its baseline an episode is
the one LeRobot's own `MetaworldEnv` + `preprocess_observation` hand a policy, bit for bit, under RoboView's keys;
every factor changes only itself and leaves the next baseline episode bit-identical; what Meta-World's scenes cannot
take is refused in one line. One env per module (building a task's env ≈ 1–3 s here)."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("metaworld", reason="Meta-World not installed (make install-metaworld)")

from roboview.eval.running import isolation  # noqa: E402
from roboview.metaworld.task import OBJECTS, baseline_metaworld_instance  # noqa: E402
from roboview.tasks import load_preset, load_task, make_env  # noqa: E402
from roboview.tasks.world import load_world  # noqa: E402
from roboview.variation.factors import FACTORS  # noqa: E402
from roboview.variation.instances import TaskInstance, generate_suite  # noqa: E402

SEED = 7
FIDELITY_TASKS = ("push-v3", "pick-place-v3", "basketball-v3")


@pytest.fixture(scope="module")
def env():
    env = make_env("metaworld", cameras=("corner2", "top"), image_size=480)
    yield env
    env.close()


def instance(task: str = "push-v3", varied: str = "color", **values) -> TaskInstance:
    base = dict(baseline_metaworld_instance(task).factors)
    return TaskInstance(varied, (varied,), base | values, "base", task="metaworld")


@pytest.mark.parametrize("task", FIDELITY_TASKS)
def test_the_baseline_is_lerobots_metaworld_episode(env, task):
    from lerobot.envs.configs import MetaworldEnv
    from lerobot.envs.factory import make_env as lerobot_make_env
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION, preprocess_observation

    vec = next(iter(next(iter(lerobot_make_env(MetaworldEnv(task=task), n_envs=1).values())).values()))
    expert = load_task("metaworld").make_expert(env)
    try:
        # A perturbed episode first: the baseline after it must still be LeRobot's episode bit for bit.
        env.reset(
            seed=SEED + 1, options={"instance": instance(task, "camera_pose", camera_pose="orbit_r1_3")}
        )
        env.step(np.zeros(4, np.float32))
        ref, _ = vec.reset(seed=[SEED], options={NEW_ROLLOUT_OPTION: True})
        ours, _ = env.reset(seed=SEED, options={"instance": instance(task)})
        expert.reset()
        successes = []
        for step in range(25):
            expected = preprocess_observation(ref)
            got = np.transpose(ours["observation.images.top"], (2, 0, 1)).astype(np.float32) / 255
            assert np.array_equal(expected["observation.image"][0].numpy(), got), (task, step)
            assert np.array_equal(ours["observation.images.corner2"], ours["observation.images.top"])
            assert np.array_equal(expected["observation.state"][0].numpy(), ours["observation.state"]), step
            action = expert.select_action(ours)
            ref, _, ref_done, _, ref_info = vec.step(action[None])
            ours, _, done, _, info = env.step(action)
            successes.append((bool(ref_info["is_success"][0]), info["is_success"]))
            if ref_done[0]:  # LeRobot resets on termination: nothing further to compare
                break
        assert all(a == b for a, b in successes), successes
    finally:
        vec.close()


def test_every_factor_changes_only_itself_and_the_next_baseline_is_unchanged():
    env = make_env("metaworld", image_size=96)
    try:
        base, _ = env.reset(seed=SEED, options={"instance": instance()})
        base = {k: np.array(v) for k, v in base.items()}
        values = {
            "color": "red",  # a re-skin: the baseline is the object's own look, `original`
            "camera_pose": "orbit_r0_2",
            "camera_euler": "6,-6",
            "dist_scale": "4",
            "lighting": "dim_left",
            "table_texture": FACTORS["table_texture"].values[1],
        }
        for factor, value in values.items():
            env.reset(seed=SEED, options={"instance": instance(varied=factor)})
            base_iso = isolation.components(env, SEED)
            varied = instance(varied=factor, **{factor: value})
            obs, _ = env.reset(seed=SEED, options={"instance": varied})
            image = np.asarray(obs["observation.images.corner2"])
            assert not np.array_equal(image, base["observation.images.corner2"]), factor
            assert np.array_equal(obs["observation.state"], base["observation.state"]), factor
            iso = isolation.components(env, SEED)
            changed = {k for k in iso if iso[k] != base_iso[k]}
            camera = {f"camera:{c}" for c in ("corner2",)}
            assert changed <= camera, (factor, changed)
            assert bool(changed) == factor.startswith(("camera", "dist")), (factor, changed)
        again, _ = env.reset(seed=SEED, options={"instance": instance()})
        for key, value in base.items():
            assert np.array_equal(np.asarray(again[key]), value), key
        # The seed draws the positions: another seed, another episode.
        other, _ = env.reset(seed=SEED + 1, options={"instance": instance()})
        assert not np.array_equal(
            np.asarray(other["observation.images.corner2"]), base["observation.images.corner2"]
        )
    finally:
        env.close()


def test_what_metaworld_cannot_take_is_refused_in_one_line():
    with pytest.raises(ValueError, match="cannot apply distractors; its factors: color, camera_pose"):
        load_world("metaworld").make_appliers({"distractors": FACTORS["distractors"].values[1]}, "metaworld")
    with pytest.raises(ValueError, match="metaworld_task.*'reach-v9'.*allowed: push-v3"):
        make_env("metaworld", image_size=64).reset(
            seed=0, options={"instance": instance(metaworld_task="reach-v9")}
        )
    with pytest.raises(ValueError, match="take control='xyz_delta' only"):
        make_env("metaworld", control="joint")
    with pytest.raises(ValueError, match="no camera 'front'; allowed: corner2, top"):
        make_env("metaworld", cameras=("front",))


def test_a_policy_that_does_not_fit_metaworld_is_refused_before_any_episode():
    from roboview.policies.fit import fit_policy
    from roboview.policies.types import policy_config

    expert = policy_config("expert")
    fit_policy(expert, ["metaworld"])
    assert expert.env_control() == "xyz_delta"  # the world's only control
    with pytest.raises(ValueError, match="takes control xyz_delta; --policy.type=vision acts in 'joint'"):
        fit_policy(policy_config("vision", control="joint"), ["metaworld"])


def test_the_metaworld_presets():
    tiny = generate_suite(load_preset("metaworld_tiny"))
    assert {i.get("metaworld_task") for i in tiny} == {"push-v3"}
    full = generate_suite(load_preset("metaworld"))
    assert {i.get("metaworld_task") for i in full} == set(OBJECTS)
    # Every value of the six factors LIBERO's full preset varies too, per task.
    assert len(full) == len(OBJECTS) * len(generate_suite(load_preset("libero"))) // 40
