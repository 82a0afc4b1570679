"""The `vision` policy perceives from pixels alone: accurate at baseline, biased by colour.

Privileged state (object pose, box center) is read here only to grade what the policy perceived.
"""

import numpy as np
import pytest

from roboview.policies.base import Episode
from roboview.policies.factory import make_policy
from roboview.policies.perception import PerceptionError, perceive
from roboview.policies.types import load_policy_types, policy_config
from roboview.tasks.env import DEPTH_KEY, IMAGE_KEY
from roboview.tasks.pick_place import BOX_CENTER, PickPlaceEnv
from roboview.variation.factors import baselines
from roboview.variation.instances import TaskInstance, episode_seed

pytestmark = pytest.mark.slow

CAMERA = "front"


def _instance(**factors: str) -> TaskInstance:
    varied = tuple(factors) or ("color",)
    return TaskInstance("color", varied, dict(baselines(), **factors), "base")


@pytest.fixture(scope="module")
def rgbd_env():
    env = PickPlaceEnv(cameras=(CAMERA,), depth=True, image_size=224)
    yield env
    env.close()


def _perceive(env: PickPlaceEnv, instance: TaskInstance, seed: int):
    obs, _ = env.reset(seed=seed, options={"instance": instance})
    return perceive(
        obs[IMAGE_KEY.format(CAMERA)], obs[DEPTH_KEY.format(CAMERA)], env.scene.camera_pose(CAMERA)
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_baseline_perception_within_2cm(rgbd_env, seed):
    seen = _perceive(rgbd_env, _instance(), seed)
    true_pos, _ = rgbd_env.object_pose()
    assert np.linalg.norm(seen.object_pos - true_pos) < 0.02
    assert np.linalg.norm(seen.box_xy - BOX_CENTER) < 0.02
    assert seen.symmetry == pytest.approx(np.pi / 2)  # a cube's footprint is square


def test_perception_changes_with_colour(rgbd_env):
    red = _perceive(rgbd_env, _instance(), 0)
    true_pos, _ = rgbd_env.object_pose()
    # Gold falls in the box's yellow range, so the object disappears into the box mask.
    with pytest.raises(PerceptionError, match="object not found"):
        _perceive(rgbd_env, _instance(color="gold"), 0)
    # Dark grey is close to the table's own colour: nothing salient is left to find.
    with pytest.raises(PerceptionError, match="object not found"):
        _perceive(rgbd_env, _instance(color="darkgray"), 0)
    # Mid grey is only partly separated from the table: found, but off-center and less salient.
    gray = _perceive(rgbd_env, _instance(color="gray"), 0)
    assert np.linalg.norm(gray.object_pos - true_pos) > 2 * np.linalg.norm(red.object_pos - true_pos)
    assert gray.object_pixels < red.object_pixels / 2
    assert gray.saliency < red.saliency / 2


def test_registered_with_camera_option():
    assert "vision" in load_policy_types()
    config = policy_config("vision")
    assert config.depth
    assert config.observed_cameras() == ("front",)
    assert policy_config("vision", camera="left_top").observed_cameras() == ("left_top",)
    with pytest.raises(ValueError, match="allowed"):
        policy_config("vision", camera="ceiling")
    with pytest.raises(TypeError, match="unexpected keyword argument 'zoom'"):  # unknown option
        policy_config("vision", zoom="2")


def _rollout(env: PickPlaceEnv, policy, instance: TaskInstance, repeat: int) -> tuple[bool, list[np.ndarray]]:
    seed = episode_seed(instance.context_id, repeat)
    obs, _ = env.reset(seed=seed, options={"instance": instance})
    policy.reset(Episode.of(env, seed))
    actions = []
    for _ in range(env.max_steps):
        actions.append(policy.select_action(obs))
        obs, _, terminated, truncated, _ = env.step(actions[-1])
        if terminated or truncated:
            return terminated, actions
    return False, actions


def test_succeeds_at_baseline_and_holds_still_when_blind(rgbd_env):
    policy = make_policy(policy_config("vision"), rgbd_env)
    baseline = _instance()
    for repeat in range(2):
        success, _ = _rollout(rgbd_env, policy, baseline, repeat)
        assert success and policy.failure_reason == ""
    # A yellow object is never found: the policy reports why and holds its pose with the gripper open.
    rgbd_env.max_steps = 5
    try:
        success, actions = _rollout(rgbd_env, policy, _instance(color="yellow"), 0)
    finally:
        rgbd_env.max_steps = 120
    assert not success and policy.failure_reason == "object not found"
    assert all(np.array_equal(a, actions[0]) for a in actions) and actions[0][7] == 0.0
