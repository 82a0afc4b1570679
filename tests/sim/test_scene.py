"""Real simulator, small sizes: every factor value builds and renders a frame that shows the object."""

import mujoco
import numpy as np
import pytest

from roboview.sim.cameras import BASE_CAMERAS, WORKSPACE_CENTER
from roboview.tasks.env import EE_STATE_KEY, IMAGE_KEY, STATE_KEY, baseline_instance
from roboview.tasks.pick_place import PickPlaceEnv
from roboview.variation.colors import COLORS
from roboview.variation.factors import FACTORS, baselines
from roboview.variation.factors.camera import (
    apply_distance,
    apply_euler,
    orbital_pose,
    scene_camera_poses,
)
from roboview.variation.instances import TaskInstance

pytestmark = pytest.mark.slow

OBSERVED = ("front", "left_top")


def make_instance(**values) -> TaskInstance:
    factors = baselines() | values
    varied = tuple(values) or ("color",)
    return TaskInstance(split="test", varied=varied, factors=factors, context_subspace="base")


_SEGMENTERS: dict[int, mujoco.Renderer] = {}


def object_pixels(env: PickPlaceEnv, camera: str) -> int:
    """Pixels of the active object in `camera`'s segmentation render."""
    if id(env) not in _SEGMENTERS:
        _SEGMENTERS[id(env)] = env.new_renderer()
        _SEGMENTERS[id(env)].enable_segmentation_rendering()
    renderer = _SEGMENTERS[id(env)]
    renderer.update_scene(env.data, camera=env.scene.ids.cameras[camera])
    seg = renderer.render()
    geom = env.scene.ids.shape_geom[env.shape]
    return int(np.sum((seg[..., 0] == geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)))


@pytest.mark.parametrize("factor", ["camera_pose", "camera_euler", "dist_scale", "initial_position", "shape"])
def test_every_value_renders_the_object(env, factor):
    for value in FACTORS[factor].values:
        obs, _ = env.reset(options={"instance": make_instance(**{factor: value})})
        for cam in OBSERVED:
            img = obs[IMAGE_KEY.format(cam)]
            assert img.shape == (96, 96, 3) and img.dtype == np.uint8
            assert img.std() > 5, f"{factor}={value}: blank {cam} frame"
            assert object_pixels(env, cam) >= 4, f"{factor}={value}: object not visible from {cam}"


def test_every_color_renders_in_its_own_color(env):
    means = {}
    for name, color in COLORS.items():
        obs, _ = env.reset(seed=0, options={"instance": make_instance(color=name)})
        assert np.allclose(env.model.geom_rgba[env.scene.ids.shape_geom["cube"]][:3], color.rgb)
        front = obs[IMAGE_KEY.format("front")]
        assert object_pixels(env, "front") >= 4
        means[name] = front.reshape(-1, 3).mean(0)
    # Only the object changes between colors, so frames of distinct colors must differ.
    assert not np.allclose(means["red"], means["blue"])
    assert means["white"].sum() > means["black"].sum()
    assert len(means) == 141


def test_reset_is_deterministic_and_seeded():
    env_a, env_b = PickPlaceEnv(image_size=64), PickPlaceEnv(image_size=64)
    inst = make_instance(color="teal", shape="cylinder")
    rng = np.random.default_rng(0)
    actions = [
        env_a.action_space.low
        + rng.random(8).astype(np.float32) * (env_a.action_space.high - env_a.action_space.low) * 0.1
        for _ in range(5)
    ]
    runs = []
    for env in (env_a, env_b, env_a):
        obs, _ = env.reset(seed=123, options={"instance": inst})
        traj = [obs]
        for a in actions:
            traj.append(env.step(a)[0])
        runs.append(traj)
    for other in runs[1:]:
        for o1, o2 in zip(runs[0], other):
            for key in o1:
                np.testing.assert_array_equal(o1[key], o2[key])
    obs_other_seed, _ = env_a.reset(seed=124, options={"instance": inst})
    assert not np.array_equal(
        obs_other_seed[IMAGE_KEY.format("front")], runs[0][0][IMAGE_KEY.format("front")]
    )
    env_a.close(), env_b.close()


def test_observation_and_action_spaces(env):
    obs, info = env.reset(options={"instance": baseline_instance()})
    assert set(obs) == {IMAGE_KEY.format(c) for c in ("front", "left_top", "right_top", "wrist")} | {
        STATE_KEY,
        EE_STATE_KEY,
    }
    assert obs[STATE_KEY].shape == (8,) and env.action_space.shape == (8,)
    assert info["task"] == baselines()["instruction"]
    # Holding the current joints with the gripper open leaves the arm where it is.
    obs2, reward, terminated, truncated, _ = env.step(np.append(obs[STATE_KEY][:7], 0.0))
    np.testing.assert_allclose(obs2[STATE_KEY][:7], obs[STATE_KEY][:7], atol=2e-3)
    assert (reward, terminated, truncated) == (0.0, False, False)


def test_depth_is_available():
    env = PickPlaceEnv(cameras=("front",), image_size=48, depth=True)
    obs, _ = env.reset()
    depth = obs["observation.depth.front"]
    assert depth.shape == (48, 48) and depth.dtype == np.float32
    assert 0.3 < float(np.median(depth)) < 3.0  # metres to the table
    env.close()


def test_bad_env_arguments_raise_with_allowed_values():
    with pytest.raises(ValueError, match="top_down.*allowed: front, left_top, right_top, wrist"):
        PickPlaceEnv(cameras=("top_down",))
    with pytest.raises(ValueError, match="fps=7"):
        PickPlaceEnv(fps=7)
    with pytest.raises(ValueError, match="unknown color 'grey'"):
        make_instance(color="grey")
    with pytest.raises(ValueError, match="unknown camera_euler '3,0'"):
        make_instance(camera_euler="3,0")


def test_camera_extrinsics_follow_the_factor():
    base = BASE_CAMERAS["front"]
    for yaw, pitch in [(6, 0), (0, -6), (6, 6)]:
        turned = apply_euler(base, yaw, pitch)
        angle = np.degrees(np.arccos(np.clip(base.optical_axis @ turned.optical_axis, -1, 1)))
        expected = np.degrees(np.arccos(np.cos(np.radians(yaw)) * np.cos(np.radians(pitch))))
        assert angle == pytest.approx(expected, abs=1e-6)
        assert turned.pos == base.pos
    for k in range(9):
        moved = apply_distance(base, k)
        shift = np.asarray(moved.pos) - np.asarray(base.pos)
        assert np.linalg.norm(shift) == pytest.approx(0.05 * k, abs=1e-9)
        if k:
            assert shift / np.linalg.norm(shift) @ base.optical_axis == pytest.approx(-1.0)
    for value in FACTORS["camera_pose"].values:
        pose = orbital_pose("front", value)
        to_center = WORKSPACE_CENTER - np.asarray(pose.pos)
        assert pose.optical_axis @ (to_center / np.linalg.norm(to_center)) == pytest.approx(1.0)
    poses = scene_camera_poses("orbit_r1_3", "0,0", "0")
    assert poses["front"].pos == poses["left_top"].pos  # both observed cameras move together
    assert poses["right_top"] == BASE_CAMERAS["right_top"]  # never perturbed


def test_gym_make_passes_the_gymnasium_env_checker():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    env = gym.make("RoboView/PickPlace-v0", image_size=32, cameras=["left_top"])
    assert env.spec.max_episode_steps == 120 and env.unwrapped.render_mode == "rgb_array"
    check_env(env.unwrapped)  # gymnasium's recommendation: the raw env behind gym.make's wrappers
    env.reset(seed=1)
    assert env.render().shape == (32, 32, 3)
    env.close()
    with pytest.raises(ValueError, match="render_mode='human' unsupported"):
        PickPlaceEnv(image_size=32, cameras=["front"], render_mode="human")


def test_an_unstable_simulation_ends_the_episode_as_a_failure():
    # Joint targets near the lower limits make MuJoCo find NaN accelerations at the third step and
    # reset the state on its own; the env must not carry on as if the episode continued.
    env = PickPlaceEnv(image_size=32, cameras=["front"])
    rng = np.random.default_rng(0)
    actions = [
        env.action_space.low
        + rng.random(8).astype(np.float32) * (env.action_space.high - env.action_space.low) * 0.1
        for _ in range(5)
    ]
    env.reset(seed=123, options={"instance": baseline_instance()})
    results = [env.step(a) for a in actions[:3]]
    assert [r[3] for r in results] == [False, False, True] and not any(r[2] for r in results)
    assert results[2][4]["failure_reason"] == "simulation unstable" and env.unstable
    env.reset(seed=123, options={"instance": baseline_instance()})
    assert not env.unstable  # a new episode starts clean
    env.close()
