"""End-effector control (docs/control.md): action layouts, the EE state, the controller, determinism."""

import gymnasium as gym
import numpy as np
import pytest

from roboview.sim.control import EE_ACTION_NAMES, axis_angle, rotation_matrix
from roboview.tasks import load_task
from roboview.tasks.env import CONTROLS, EE_STATE_KEY, EE_STATE_NAMES, STATE_KEY, action_names
from roboview.tasks.pick_place import PickPlaceEnv

pytestmark = pytest.mark.slow

OPEN, CLOSE = -1.0, 1.0
EE_REPO = "t/ee_demos"


@pytest.fixture(scope="module")
def envs():
    made = {c: PickPlaceEnv(cameras=("front",), image_size=16, lazy=True, control=c) for c in CONTROLS}
    yield made
    for env in made.values():
        env.close()


def rotation_error(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between two orientations given as axis-angle."""
    return float(np.linalg.norm(axis_angle(rotation_matrix(a) @ rotation_matrix(b).T)))


def test_unknown_control_names_the_allowed_values():
    assert CONTROLS == ("joint", "ee_delta", "ee_abs")
    with pytest.raises(ValueError, match="unknown control 'osc'; allowed: joint, ee_delta, ee_abs"):
        PickPlaceEnv(control="osc")
    with pytest.raises(ValueError, match="allowed: joint, ee_delta, ee_abs"):
        gym.make(load_task("pick_place").gym_id, control="cartesian")


def test_action_and_observation_spaces(envs):
    assert envs["joint"].action_space.shape == (8,)
    delta, absolute = envs["ee_delta"].action_space, envs["ee_abs"].action_space
    assert delta.shape == absolute.shape == (7,) and delta.dtype == np.float32
    np.testing.assert_array_equal(delta.low, -1.0), np.testing.assert_array_equal(delta.high, 1.0)
    assert absolute.high[2] == 1.5 and absolute.high[3] == np.float32(np.pi) and absolute.low[6] == -1.0
    assert action_names("ee_delta") == EE_ACTION_NAMES["ee_delta"] and len(action_names("joint")) == 8
    for control, env in envs.items():
        assert env.observation_space[EE_STATE_KEY].shape == (len(EE_STATE_NAMES),) == (8,)
        obs, _ = env.reset(seed=3)
        assert set(obs) == {"observation.images.front", STATE_KEY, EE_STATE_KEY}, control
        np.testing.assert_array_equal(obs[EE_STATE_KEY], env.ee_state())
        assert obs[EE_STATE_KEY].dtype == np.float32


def test_ee_state_at_home_and_gripper_openings(envs):
    env = envs["ee_abs"]
    obs, _ = env.reset(seed=3)
    state = obs[EE_STATE_KEY]
    # The pinch point sits 44 cm in front of the base, 34 cm up, pointing straight down (π about x).
    np.testing.assert_allclose(state[:3], [0.4444, 0.0, 0.3368], atol=1e-3)
    np.testing.assert_allclose(rotation_matrix(state[3:6]), np.diag([1.0, -1.0, -1.0]), atol=2e-3)
    # Open: each pad face 42.6 mm from the pinch point (the 2F-85's 85 mm stroke), mirrored.
    np.testing.assert_allclose(state[6:], [0.0427, -0.0427], atol=1e-3)
    hold = np.append(state[:6], CLOSE).astype(np.float32)
    for _ in range(10):
        obs, *_ = env.step(hold)
    assert 0 <= obs[EE_STATE_KEY][6] < 3e-3 and -3e-3 < obs[EE_STATE_KEY][7] <= 0
    assert obs[STATE_KEY][7] > 0.95  # the joint state's closure says the same


def test_ee_abs_reaches_the_commanded_pose(envs):
    env = envs["ee_abs"]
    obs, _ = env.reset(seed=3)
    start = obs[EE_STATE_KEY]
    rotation = rotation_matrix([0.0, 0.0, 0.3]) @ rotation_matrix(start[3:6])  # 0.3 rad about the vertical
    target = np.array([*(start[:3] + [0.05, -0.05, -0.1]), *axis_angle(rotation), OPEN], np.float32)
    for _ in range(10):
        obs, *_ = env.step(target)
    reached = obs[EE_STATE_KEY]
    np.testing.assert_allclose(reached[:3], target[:3], atol=5e-4)
    assert rotation_error(reached[3:6], target[3:6]) < 5e-3


def test_ee_delta_moves_relative_to_the_current_pose(envs):
    env = envs["ee_delta"]
    ids = env.scene.ids
    obs, _ = env.reset(seed=3)
    start = obs[EE_STATE_KEY]
    for _ in range(3):  # zero delta, gripper open: the arm holds its pose
        obs, *_ = env.step(np.array([0, 0, 0, 0, 0, 0, OPEN], np.float32))
    np.testing.assert_allclose(obs[EE_STATE_KEY], start, atol=2e-4)
    before = obs[EE_STATE_KEY]
    obs, *_ = env.step(np.array([1, 0, 0, 0, 0, 0, OPEN], np.float32))  # +x: 0.05 m asked, lagging servos
    moved = obs[EE_STATE_KEY][:3] - before[:3]
    assert 0.04 < moved[0] <= 0.0501 and np.abs(moved[1:]).max() < 3e-3
    before = obs[EE_STATE_KEY]
    obs, *_ = env.step(np.array([0, 0, 0, 0, 0, 0.2, OPEN], np.float32))  # 0.1 rad about base z
    turn = axis_angle(rotation_matrix(obs[EE_STATE_KEY][3:6]) @ rotation_matrix(before[3:6]).T)
    assert 0.08 < turn[2] <= 0.101 and np.abs(turn[:2]).max() < 5e-3
    # Far out of reach: the joint targets stay inside the joint range.
    low, high = ids.arm_range[:, 0], ids.arm_range[:, 1]
    for _ in range(25):
        env.step(np.array([1, 0, 1, 0, 1, 0, OPEN], np.float32))
        ctrl = env.data.ctrl[ids.arm_actuators]
        assert np.all(ctrl >= low) and np.all(ctrl <= high)


@pytest.mark.parametrize("control", ["ee_delta", "ee_abs"])
def test_same_actions_give_bit_identical_trajectories(envs, control):
    env = envs[control]
    space = env.action_space
    actions = np.random.default_rng(7).uniform(space.low, space.high, (12, 7)).astype(np.float32)
    if control == "ee_abs":  # reachable targets: within 10 cm of home
        actions[:, :3] = np.float32([0.44, 0.0, 0.30]) + 0.1 * (actions[:, :3] / space.high[:3])
    runs = []
    for _ in range(2):
        env.reset(seed=11)
        runs.append([env.step(a)[0][EE_STATE_KEY].tobytes() + env.data.qpos.tobytes() for a in actions])
    assert runs[0] == runs[1]


@pytest.fixture(scope="module")
def ee_demos(tmp_path_factory):
    """2 expert demos collected with `--dataset.control=ee_delta` (front camera, 64²): the dataset root."""
    from roboview.pipelines.collect import main

    root = tmp_path_factory.mktemp("ee") / "ds"
    result = main(
        [
            f"--dataset.repo_id={EE_REPO}",
            f"--dataset.root={root}",
            "--dataset.num_episodes=2",
            "--dataset.image_size=64",
            "--dataset.cameras=[front]",
            "--dataset.control=ee_delta",
            "--num_workers=1",
        ]
    )
    assert result.episodes == 2
    return root


def test_ee_delta_demos_read_back_with_lerobot_and_replay(ee_demos):
    """The dataset holds the EE state and action, named; replaying the recorded actions in a fresh env with the
    episode's seed gives back the recorded states, bit for bit, and succeeds."""
    import json

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from roboview.demos.dataset import PROGRESS_FILE, read_provenance
    from roboview.demos.recorder import training_instance

    ds = LeRobotDataset(EE_REPO, root=ee_demos)
    features = ds.meta.features
    assert features[STATE_KEY]["shape"] == (8,) and features[STATE_KEY]["names"] == list(EE_STATE_NAMES)
    assert features["action"]["shape"] == (7,)
    assert features["action"]["names"] == list(EE_ACTION_NAMES["ee_delta"])
    assert json.loads((ee_demos / PROGRESS_FILE).read_text())["signature"]["control"] == "ee_delta"
    assert "Control: `ee_delta`" in (ee_demos / "README.md").read_text()

    frames = ds.hf_dataset.with_format("numpy")[:]  # every frame: column -> array
    episode_index, states, actions = frames["episode_index"], frames[STATE_KEY], frames["action"]
    provenance, _ = read_provenance(ee_demos)
    env = PickPlaceEnv(cameras=("front",), image_size=16, lazy=True, control="ee_delta")
    for row in provenance.itertuples():
        mine = episode_index == row.episode_index
        seed = int(row.episode_seed)
        obs, _ = env.reset(seed=seed, options={"instance": training_instance(np.random.default_rng(seed))})
        replayed, success = [], False
        for action in actions[mine]:
            replayed.append(obs[EE_STATE_KEY])
            obs, _, success, _, _ = env.step(action)
        np.testing.assert_array_equal(np.stack(replayed), states[mine])
        assert success and np.abs(actions[mine]).max() <= 1.0
    env.close()


def test_a_checkpoint_trained_on_ee_demos_acts_in_their_control(ee_demos, tmp_path):
    """roboview.pipelines.train (1 step) on the ee_delta demos: the `lerobot` type reads ee_delta from the checkpoint, the env
    is made in it, and the model's observation.state is the env's EE state (not the joint state)."""
    from roboview.policies.factory import make_policy
    from roboview.policies.types import policy_config
    from tests.helpers import cli

    out = tmp_path / "train"
    args = [f"--dataset.repo_id={EE_REPO}", f"--dataset.root={ee_demos}", f"--output_dir={out}"]
    proc = cli.run(
        "roboview.pipelines.train",
        *args,
        "--batch_size=2",
        "--steps=1",
        "--save_freq=1",
        "--device=cpu",
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    checkpoint = str(out / "checkpoints" / "last" / "pretrained_model")
    config = policy_config("lerobot", path=checkpoint, device="cpu")
    assert config.env_control() == "ee_delta" and config.observed_cameras() == ("front",)
    with pytest.raises(
        ValueError, match="--policy.control='ee_abs' but the checkpoint .* acts in 'ee_delta'"
    ):
        policy_config("lerobot", path=checkpoint, device="cpu", control="ee_abs")
    env = PickPlaceEnv(cameras=("front",), image_size=config.input_image_size(), control=config.env_control())
    policy = make_policy(config, env)
    obs, _ = env.reset(seed=2)
    chunk = policy.predict_chunks({0: obs})[0]
    assert np.shape(chunk[0]) == (7,)
    moved_ee = dict(obs) | {EE_STATE_KEY: obs[EE_STATE_KEY] + np.float32(0.05)}
    moved_joints = dict(obs) | {STATE_KEY: obs[STATE_KEY] + np.float32(0.05)}
    assert not np.array_equal(policy.predict_chunks({0: moved_ee})[0], chunk)
    np.testing.assert_array_equal(policy.predict_chunks({0: moved_joints})[0], chunk)
    obs, *_ = env.step(chunk[0])
    policy.close(), env.close()


def test_policy_types_act_in_the_control_they_are_given(envs):
    from roboview.policies.base import Episode, JointPlanInEE
    from roboview.policies.factory import make_policy
    from roboview.policies.types import policy_config

    expert = policy_config("expert", control="ee_abs")
    assert expert.env_control() == expert.control == "ee_abs" and "control" not in expert.options()
    assert policy_config("vision").env_control() == "joint"
    with pytest.raises(ValueError, match="unknown --policy.control='osc'; allowed: joint, ee_delta, ee_abs"):
        policy_config("random", control="osc")
    # An agent that plans joint targets acts through their EE action: here the random floor.
    env = envs["ee_delta"]
    policy = make_policy(policy_config("random", control="ee_delta"), env)
    assert isinstance(policy, JointPlanInEE) and policy.name == "random" and policy.failure_reason == ""
    obs, _ = env.reset(seed=5)
    policy.reset(Episode.of(env, 5))
    for _ in range(3):
        action = policy.select_action(obs)
        assert action.shape == (7,) and action.dtype == np.float32 and np.abs(action).max() <= 1.0
        obs, *_ = env.step(action)
    assert not np.allclose(obs[EE_STATE_KEY][:3], env.reset(seed=5)[0][EE_STATE_KEY][:3], atol=1e-3)
