"""`scene_text` in RoboView's scene: the words and their pixels, the card only in scenes of instances that set the
factor (every other scene, id and pixel as before), only the texture differing across its values, the gate's
legibility and occlusion measures, and the split compared against its blank card."""

import numpy as np
import pandas as pd
import pytest

from roboview.eval.running import isolation
from roboview.eval.statistics.compare import control_deltas, control_rows
from roboview.tasks import make_env
from roboview.tasks.env import IMAGE_KEY, baseline_instance
from roboview.tasks.fairness import FairnessThresholds, factor_gates
from roboview.variation.factors import baselines, load_factor
from roboview.variation.factors.scene_text import (
    MIN_GLYPH_PX,
    VALUES,
    WORDS,
    card_image,
    glyph_height,
    goal_words,
    legibility_reasons,
    text_of,
)
from roboview.variation.instances import TaskInstance
from tests.helpers.text import reading

pytestmark = pytest.mark.slow

CAMERAS = ("front", "left_top")


def instance(value: str, task: str = "pick_place", **context) -> TaskInstance:
    values = baselines(task) | context | ({"scene_text": value} if value != "none" else {})
    return TaskInstance("scene_text", ("scene_text",), values, "base", task=task)


@pytest.fixture(scope="module")
def env():
    env = make_env("pick_place", cameras=(*CAMERAS, "wrist"), image_size=224)
    yield env
    env.close()


def frames(env, inst):
    obs, _ = env.reset(options={"instance": inst})
    return {c: np.asarray(obs[IMAGE_KEY.format(c)]) for c in env.cameras}


def test_words_and_pixels():
    assert [text_of(v, WORDS["pick_place"]) for v in VALUES] == [
        ("", ""),
        ("BOX", "normal"),
        ("LEFT", "normal"),
        ("GREEN", "normal"),
        ("ZORP", "normal"),
        ("BOX", "small"),
        ("BOX", "large"),
    ]
    with pytest.raises(ValueError, match=r"unknown scene_text 'huge'; allowed: none, blank, target"):
        text_of("huge", WORDS["pick_place"])
    assert (card_image("") == card_image("")[0, 0]).all()  # blank: paper only
    ink = {
        size: int((card_image("BOX", size).min(axis=-1) < 128).any(axis=1).sum())
        for size in ("small", "normal", "large")
    }
    assert ink["small"] < ink["normal"] < ink["large"]  # rows holding ink: the capitals' height
    assert abs(ink["large"] - 0.75 * card_image("").shape[0]) <= 3  # BOX: as tall as the card lets it
    assert goal_words("pick up the alphabet soup and place it in the basket") == (
        goal_words("put the cream cheese in the basket")
    )
    assert goal_words("put both the cream cheese box and the butter in the basket").target == "BASKET"
    assert goal_words("put the bowl on the plate").conflict == "BASKET"
    with pytest.raises(ValueError, match="names none of the goal nouns"):
        goal_words("wave hello")


def test_glyph_height_measures_the_text_line():
    blank = np.zeros((60, 80, 3), np.uint8)
    text = blank.copy()
    text[20:32, 10:70] = 255  # a 12-row line
    assert glyph_height(text, blank) == pytest.approx(12, abs=1)
    assert glyph_height(text.transpose(1, 0, 2), blank.transpose(1, 0, 2)) == pytest.approx(12, abs=1)
    assert glyph_height(blank, blank) == 0.0
    assert legibility_reasons({"front": 5.0, "left_top": 9.0}, 224) == [
        f"front: text glyphs 5.0 px < {MIN_GLYPH_PX:.1f} at 224²"
    ]


def test_card_only_where_the_factor_is_set(env):
    fresh = make_env("pick_place", cameras=(*CAMERAS, "wrist"), image_size=224)
    try:
        plain = frames(fresh, baseline_instance())
        xml, ngeom = fresh.scene_xml(), fresh.model.ngeom
    finally:
        fresh.close()
    assert "scene_text" not in xml and env.text_card() is None
    assert (
        instance("none").instance_id
        == TaskInstance("scene_text", ("scene_text",), baselines(), "base").instance_id
    )
    frames(env, instance("target"))
    assert env.model.ngeom == ngeom + 1 and env.text_card() is not None
    again = frames(env, baseline_instance())  # back to the plain scene: bit for bit a fresh env's
    assert env.model.ngeom == ngeom and env.scene_xml() == xml
    for cam in plain:
        np.testing.assert_array_equal(again[cam], plain[cam])


def test_only_the_texture_differs_and_the_gate_passes(env):
    shots, certs, heights = {}, {}, {}
    for value in VALUES:
        inst = instance(value)
        shots[value] = frames(env, inst)
        certs[value] = isolation.components(env, inst.seed)
        heights[value] = env.text_card().glyph_heights(list(CAMERAS), shots[value])
        assert env.text_card().hidden(list(CAMERAS)) == {"front": 0, "left_top": 0}
        assert factor_gates(env, shots[value]) == [], value
    assert len({tuple(sorted(c.items())) for c in certs.values()}) == 1  # card pose, robot, object: one block
    assert "card" in certs["blank"]
    changed = np.abs(shots["target"]["front"].astype(int) - shots["blank"]["front"].astype(int)).max(-1) > 0
    rows, cols = np.nonzero(changed)
    # Only the card's pixels change: a patch in the lower part of the front view, far from the object and the box.
    assert rows.min() > 150 and cols.max() - cols.min() < 80
    assert reading(shots["conflict"]["front"], shots["blank"]["front"], "LEFT") == "upright"
    assert reading(shots["color"]["front"], shots["blank"]["front"], "GREEN") == "upright"
    assert heights["blank"] == {"front": 0.0, "left_top": 0.0}
    for cam in CAMERAS:
        assert heights["target_small"][cam] < heights["target"][cam] < heights["target_large"][cam]
        assert heights["target_small"][cam] >= MIN_GLYPH_PX
    assert FairnessThresholds()  # the gate's thresholds are untouched: the text floor is the factor's own


def test_small_text_fails_the_gate_at_a_small_image():
    env = make_env("pick_place", cameras=CAMERAS, image_size=64)
    try:
        shots = frames(env, instance("target_small"))
        reasons = factor_gates(env, shots)
    finally:
        env.close()
    assert reasons and all("text glyphs" in r and f"< {MIN_GLYPH_PX:.1f} at 64²" in r for r in reasons)


def test_physics_is_the_plain_scene_s(env):
    poses = {}
    for value in ("none", "blank", "target"):
        env.reset(options={"instance": instance(value)})
        for _ in range(5):
            env.step(np.r_[env.state()[:7], 1.0].astype(np.float32))
        poses[value] = (env.state().copy(), env.object_pose()[0].copy())
    np.testing.assert_array_equal(poses["blank"][0], poses["target"][0])
    np.testing.assert_allclose(poses["none"][0], poses["blank"][0], atol=1e-9)
    np.testing.assert_allclose(poses["none"][1], poses["blank"][1], atol=1e-9)


def test_the_split_is_compared_against_its_blank_card():
    rows = []
    for context in range(6):
        for value, success in (("blank", 1), ("target", 1), ("conflict", int(context < 1))):
            rows.append(
                {
                    "factor": "scene_text",
                    "value": value,
                    "context_id": f"c{context}",
                    "repeat": 0,
                    "success": success,
                }
            )
    split = pd.DataFrame(rows)
    elsewhere = split.assign(
        factor="color", value="red", success=0
    )  # an all-baseline arm that fails everything
    assert control_rows(elsewhere, split)["value"].unique().tolist() == ["blank"]
    deltas = control_deltas(elsewhere, split)
    assert deltas["target"]["delta_control"] == 0.0
    assert deltas["conflict"]["delta_control"] == pytest.approx(-5 / 6)
    assert (
        control_rows(elsewhere, elsewhere) is elsewhere
    )  # a factor without a reference: the all-baseline arm
    assert load_factor("scene_text").reference == "blank"
