"""A VLM agent is shown the scene's text: against the classic-CV stand-in over real HTTP, the image the agent sends
for a `scene_text` instance carries the card's word (ink on the card where the blank card has none, nowhere else),
the prompt carries the instruction, and both agents still act on the scene."""

import base64
import io

import numpy as np
import pytest
from PIL import Image

from roboview.policies.base import Episode
from roboview.policies.factory import make_policy
from roboview.policies.types import policy_config
from roboview.policies.vlm.client import Endpoint
from roboview.policies.vlm.standin import MODEL_NAME, ClassicCVModel
from roboview.tasks import make_env
from roboview.variation.factors import baselines
from roboview.variation.instances import TaskInstance, episode_seed
from tests.helpers.vlm_servers import ScriptedServer

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def standin():
    server = ScriptedServer(ClassicCVModel())
    yield server
    server.close()


@pytest.fixture(scope="module")
def env():
    env = make_env("pick_place", cameras=("front",), depth=True, image_size=224)
    yield env
    env.close()


def instance(value: str) -> TaskInstance:
    return TaskInstance("scene_text", ("scene_text",), baselines() | {"scene_text": value}, "base")


def sent_image(request: dict) -> np.ndarray:
    """The first image of a chat-completions request, decoded."""
    parts = request["messages"][-1]["content"]
    url = next(p["image_url"]["url"] for p in parts if p["type"] == "image_url")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def first_request(standin, env, tmp_path, agent: str, value: str) -> tuple[dict, bool]:
    config = policy_config(agent, endpoint=Endpoint(standin.url, MODEL_NAME, cache_dir=str(tmp_path / value)))
    policy = make_policy(config, env)
    inst = instance(value)
    seed = episode_seed(inst.context_id, 0)
    obs, _ = env.reset(seed=seed, options={"instance": inst})
    policy.reset(Episode.of(env, seed))
    n = len(standin.requests)
    success = False
    for _ in range(90):
        obs, _, success, truncated, _ = env.step(policy.select_action(obs))
        if success or truncated:
            break
    return standin.requests[n], success


@pytest.mark.parametrize("agent", ["vlm_simple", "vlm_moka"])
def test_the_agent_is_shown_the_word(standin, env, tmp_path, agent):
    blank, blank_success = first_request(standin, env, tmp_path, agent, "blank")
    word, word_success = first_request(standin, env, tmp_path, agent, "conflict")
    a, b = sent_image(blank).astype(int), sent_image(word).astype(int)
    changed = np.abs(a - b).max(axis=-1) > 0
    rows, cols = np.nonzero(changed)
    # LEFT on the card, low in the front view; the object, the box and the robot are the same pixels.
    assert rows.min() > 150 and cols.max() - cols.min() < 90
    ink = (b.max(axis=-1) < 90) & changed
    assert ink.sum() > 50 and not ((a.max(axis=-1) < 90) & changed).any()
    prompt = " ".join(p["text"] for p in word["messages"][-1]["content"] if p["type"] == "text")
    assert "put the small object into the yellow box" in prompt
    # The stand-in reads colours, not words: the card moves neither of its agents.
    assert blank_success and word_success
