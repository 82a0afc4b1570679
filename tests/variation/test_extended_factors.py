"""The `extended` preset's four visual factors: each value builds, renders and shows the object;
switching values in place restores the scene bit for bit; distractors never touch the object or the
box; the expert solves every value; the gate judges a dim light by contrast, not by colour shift."""

import time

import mujoco
import numpy as np
import pytest

from roboview.tasks import ScriptedExpert, load_preset, make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.tasks.fairness import (
    CameraFairness,
    FairnessThresholds,
    violations,
)
from roboview.variation.factors import FACTORS, baselines
from roboview.variation.factors.distractors import BODIES
from roboview.variation.instances import TaskInstance, episode_seed, generate_suite

pytestmark = pytest.mark.slow

NEW = ("lighting", "table_texture", "distractors", "object_size")


def instance(**values):
    varied = tuple(values) or ("color",)
    return TaskInstance("test", varied, baselines() | values, "base")


@pytest.fixture(scope="module")
def env():
    env = make_env("pick_place", cameras=("front", "left_top"), image_size=96)
    yield env
    env.close()


def _object_pixels(env, renderer, camera):
    renderer.update_scene(env.data, camera=env.scene.ids.cameras[camera])
    seg = renderer.render()
    return int(np.sum((seg[..., 0] == env.scene.active_geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)))


def test_every_value_renders_a_frame_that_shows_the_object(env):
    seg = env.new_renderer()
    seg.enable_segmentation_rendering()
    for factor in NEW:
        means = {}
        for value in FACTORS[factor].values:
            obs, _ = env.reset(options={"instance": instance(**{factor: value})})
            for cam in ("front", "left_top"):
                frame = obs[IMAGE_KEY.format(cam)]
                assert frame.std() > 5, f"{factor}={value}: blank {cam} frame"
                assert _object_pixels(env, seg, cam) >= 4, f"{factor}={value}: object not visible from {cam}"
            means[value] = obs[IMAGE_KEY.format("front")].astype(float).mean()
        # Every value changes what the camera sees.
        assert len(set(np.round(list(means.values()), 6))) == len(means), factor


def test_switching_in_place_restores_the_scene_exactly(env):
    base = instance()
    first, _ = env.reset(seed=3, options={"instance": base})
    model_before = [
        env.model.geom_rgba.copy(),
        env.model.geom_size.copy(),
        env.model.geom_matid.copy(),
        env.model.light_diffuse.copy(),
        env.model.body_pos.copy(),
        env.model.geom_dataid.copy(),
    ]
    for factor in NEW:
        for value in FACTORS[factor].values:
            env.reset(seed=3, options={"instance": instance(**{factor: value})})
    again, _ = env.reset(seed=3, options={"instance": base})
    for key in first:
        assert np.array_equal(first[key], again[key]), key
    model_after = [
        env.model.geom_rgba,
        env.model.geom_size,
        env.model.geom_matid,
        env.model.light_diffuse,
        env.model.body_pos,
        env.model.geom_dataid,
    ]
    assert all(np.array_equal(a, b) for a, b in zip(model_before, model_after))


def test_an_instance_switch_costs_well_under_a_frame(env):
    values = [instance(**{f: v}) for f in NEW for v in FACTORS[f].values]
    scene, rng = env.scene, np.random.default_rng(0)
    start = time.perf_counter()
    for inst in values * 20:
        for name in NEW:
            env.applier(name).apply(inst.get(name), rng)
    per_switch = (time.perf_counter() - start) / (len(values) * 20)
    assert scene.model is env.model  # in place: never recompiled
    print(f"instance switch (4 appliers): {per_switch * 1e6:.0f} µs")
    assert per_switch < 0.01


def test_distractors_never_touch_the_object_or_the_box():
    env = make_env("pick_place", cameras=("front",), image_size=32, lazy=True)
    try:
        suite = [i for i in generate_suite(load_preset("extended")) if i.split == "distractors"]
        ids = env.scene.ids
        distractors = {env.model.geom(f"distractor_{name}").id for name, *_ in BODIES}
        watched = set(ids.shape_geom.values()) | set(env.target_geoms())
        for inst in suite:
            for repeat in range(3):
                env.reset(seed=episode_seed(inst.context_id, repeat), options={"instance": inst})
                obj_xy = env.object_pose()[0][:2]
                for geom in distractors:
                    xy = env.data.geom_xpos[geom][:2]
                    if np.linalg.norm(xy) > 2.0:
                        continue  # parked
                    # 5 cm footprint radius of the distractor + 3 cm of the (jittered) object: ≥ 10 cm apart.
                    assert np.linalg.norm(xy - obj_xy) > 0.10, (inst.value, inst.context)
                    assert np.abs(xy - np.array([0.45, -0.22])).max() > 0.083 + 0.05  # clear of the box walls
                for c in env.data.contact[: env.data.ncon]:
                    pair = {c.geom1, c.geom2}
                    assert not (pair & distractors and pair & watched), (inst.value, inst.context)
    finally:
        env.close()


@pytest.mark.parametrize("factor", NEW)
def test_the_expert_solves_every_value(factor):
    env = make_env("pick_place", cameras=("front",), image_size=32, lazy=True)  # the expert reads no image
    expert = ScriptedExpert(env)
    try:
        for value in FACTORS[factor].values:
            obs, _ = env.reset(seed=1, options={"instance": instance(**{factor: value})})
            expert.reset()
            for _ in range(env.max_steps):
                obs, _, success, truncated, _ = env.step(expert.select_action(obs))
                if success or truncated:
                    break
            assert success, f"expert failed at {factor}={value}"
    finally:
        env.close()


def test_the_gate_judges_a_dim_light_by_contrast_not_by_colour_shift():
    t = FairnessThresholds()
    shifted = CameraFairness(
        "front", 1.0, 200, True, 1.0, 900, True, delta_e_nominal=60.0, delta_e_table=20.0
    )
    assert any("nominal" in r for r in violations(shifted, t, 25, True))
    assert violations(shifted, t, 25, True, judge_nominal=False) == []  # a dim light is not a failure
    hidden = CameraFairness("front", 1.0, 200, True, 1.0, 900, True, delta_e_nominal=60.0, delta_e_table=1.5)
    assert any("object-table" in r for r in violations(hidden, t, 25, True, judge_nominal=False))
    assert not FACTORS["lighting"].keeps_nominal_color and FACTORS["table_texture"].keeps_nominal_color


def test_the_dose_response_trend_recovers_a_known_slope():
    from roboview.eval.statistics.significance import logistic_trend

    rng = np.random.default_rng(0)
    x = np.arange(5.0)
    slopes = []
    for _ in range(200):
        n = np.full(5, 40.0)
        p = 1 / (1 + np.exp(-(1.5 - 0.8 * x)))
        _, slope, _ = logistic_trend(x, rng.binomial(40, p).astype(float), n)
        slopes.append(slope)
    assert abs(np.mean(slopes) + 0.8) < 0.05  # unbiased around the true slope
    _, slope, pval = logistic_trend(x, np.array([38.0, 30, 20, 10, 4]), np.full(5, 40.0))
    assert slope < 0 and pval < 1e-6
    assert logistic_trend(x, np.full(5, 40.0), np.full(5, 40.0)) is None  # no failures: no trend to fit


def test_reports_draw_the_new_factors(tmp_path):
    import pandas as pd

    from roboview.eval.reporting.report import write_report
    from roboview.variation.instances import split_task

    suite = [i for i in generate_suite(load_preset("extended")) if split_task(i.split)[1] in NEW]
    rng = np.random.default_rng(0)
    rows = []
    for inst in suite:
        for repeat in range(2):
            level = {
                "distractors": lambda v: 1 - 0.2 * int(v),
                "object_size": lambda v: 0.9,
                "lighting": lambda v: 0.3 if v.startswith("dim") else 0.9,
                "table_texture": lambda v: 0.5 if v.startswith("checker") else 0.9,
            }[split_task(inst.split)[1]](inst.value)
            success = rng.random() < level
            rows.append({**inst.to_record(), "repeat": repeat, "success": bool(success), "policy": "sim"})
    result = write_report(pd.DataFrame(rows), tmp_path, plots=True)
    for name in ("sr_lighting.png", "sr_table_texture.png", "sr_distractors.png", "sr_object_size.png"):
        for file in (name, f"push_{name}"):  # one figure per task
            assert result.plots[file] is None and (tmp_path / file).stat().st_size > 10_000, file
    table1 = (tmp_path / "report.md").read_text()
    assert "| Lighting | sim |" in table1 and "| Distractors | sim |" in table1
