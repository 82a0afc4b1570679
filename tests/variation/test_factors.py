"""The factor registry: exact values, baselines, parsers and error messages."""

import pytest

from roboview.tasks.pick_place import OBJECT_POSITIONS
from roboview.variation.colors import COLORS
from roboview.variation.factors import (
    FACTORS,
    baselines,
    context_factors,
    factor_names,
    load_factor,
    parse_camera_pose,
    parse_dist_scale,
    parse_euler,
    visual_factors,
)

pytestmark = pytest.mark.fast


def test_factor_names_and_kinds():
    # The paper's four visual factors, then the `extended` preset's four (docs/formats.md, "Factors": names and counts fixed).
    assert visual_factors() == (
        "color",
        "camera_pose",
        "camera_euler",
        "dist_scale",
        "lighting",
        "table_texture",
        "distractors",
        "object_size",
        "scene_text",
        # LIBERO-plus's camera sub-factors (the LIBERO wing's; RoboView's and Meta-World's scenes lack them).
        "view_azimuth",
        "view_elevation",
        "view_scale",
        "view_rotz",
        "view_roty",
        # LIBERO-plus's sensor noise (the LIBERO wing's): one factor per type, severity 1–10, and the wrist camera.
        "noise_motion_blur",
        "noise_gaussian_blur",
        "noise_zoom_blur",
        "noise_fog",
        "noise_glass_blur",
        "noise_wrist",
        # LIBERO-plus's light and background scenes (the LIBERO wing's): its problem classes.
        "scene_light",
        "scene_background",
    )
    assert context_factors() == ("initial_position", "shape", "instruction")
    assert factor_names() == visual_factors() + context_factors()
    worlds = {f for t in ("libero", "liberoplus", "metaworld") for f in context_factors(t)}
    assert set(FACTORS) == set(factor_names()) | set(context_factors("push")) | worlds
    assert [load_factor(n).kind for n in factor_names()] == ["visual"] * 22 + ["context"] * 3
    assert {n: len(load_factor(n).values) for n in visual_factors()[9:14]} == {
        "view_azimuth": 150,
        "view_elevation": 1,
        "view_scale": 100,
        "view_rotz": 10,
        "view_roty": 10,
    }
    assert {n: len(load_factor(n).values) for n in visual_factors()[14:]} == {
        **{f"noise_{t}": 10 for t in ("motion_blur", "gaussian_blur", "zoom_blur", "fog", "glass_blur")},
        "noise_wrist": 1,
        "scene_light": 998,
        "scene_background": 921,
    }
    assert {n: len(load_factor(n).values) for n in visual_factors()[4:9]} == {
        "lighting": 9,
        "table_texture": 8,
        "distractors": 5,
        "object_size": 7,
        "scene_text": 7,
    }


def test_baselines():
    assert baselines() == {
        "color": "red",
        "camera_pose": "original",
        "camera_euler": "0,0",
        "dist_scale": "0",
        "lighting": "default",
        "table_texture": "plain",
        "distractors": "0",
        "object_size": "1.0",
        "scene_text": "none",
        "view_azimuth": "0",
        "view_elevation": "0",
        "view_scale": "100",
        "view_rotz": "0",
        "view_roty": "0",
        **{
            f"noise_{t}": "0"
            for t in ("motion_blur", "gaussian_blur", "zoom_blur", "fog", "glass_blur", "wrist")
        },
        "scene_light": "original",
        "scene_background": "original",
        "initial_position": "center",
        "shape": "cube",
        "instruction": "put the small object into the yellow box",
    }
    # Every baseline is one of its factor's values, except where no change is not a swept value: camera_pose's
    # "original" (the unperturbed cameras), LIBERO-plus's no-change view, its noise-free frame and LIBERO's own scene,
    # and scene_text's "none" (no card: the scene of every instance that does not set it; its split's control arm is
    # the blank card).
    unswept = {"camera_pose", "view_azimuth", "view_elevation", "view_scale", "view_rotz", "view_roty"}
    unswept |= {"scene_light", "scene_background"}
    unswept |= {"scene_text"} | {
        f"noise_{t}" for t in ("motion_blur", "gaussian_blur", "zoom_blur", "fog", "glass_blur", "wrist")
    }
    assert all(load_factor(n).baseline in load_factor(n).values for n in factor_names() if n not in unswept)
    assert not any(load_factor(n).baseline in load_factor(n).values for n in unswept)


def test_color_values():
    color = load_factor("color")
    assert color.values == tuple(sorted(COLORS))
    assert len(color.values) == 141


def test_camera_pose_values_and_baseline_outside_sweep():
    pose = load_factor("camera_pose")
    assert len(pose.values) == 21
    assert pose.values[:2] == ("orbit_r0_0", "orbit_r0_1")
    assert pose.values[7] == "orbit_r1_0"
    assert pose.values[-1] == "orbit_r2_6"
    assert "original" not in pose.values
    assert pose.is_valid("original")
    assert pose.validate("original") == "original"
    assert parse_camera_pose("orbit_r2_3") == (2, 3)
    assert parse_camera_pose("original") is None
    with pytest.raises(ValueError, match="'orbit_r3_0'"):
        parse_camera_pose("orbit_r3_0")


def test_camera_euler_values_and_parser():
    euler = load_factor("camera_euler")
    assert euler.values == (
        "-6,-6",
        "-6,0",
        "-6,6",
        "0,-6",
        "0,0",
        "0,6",
        "6,-6",
        "6,0",
        "6,6",
    )
    assert parse_euler("-6,6") == (-6, 6)
    assert parse_euler("0,0") == (0, 0)
    with pytest.raises(ValueError, match=r"unknown camera_euler '3,0'; allowed: -6,-6"):
        parse_euler("3,0")


def test_dist_scale_values_and_parser():
    assert load_factor("dist_scale").values == tuple(str(k) for k in range(9))
    assert parse_dist_scale("8") == 8
    assert parse_dist_scale("0") == 0
    with pytest.raises(ValueError, match="unknown dist_scale '9'"):
        parse_dist_scale("9")


def test_context_factor_values():
    assert load_factor("initial_position").values == ("center", "left", "right", "near")
    assert tuple(OBJECT_POSITIONS) == load_factor("initial_position").values
    assert OBJECT_POSITIONS["center"] == (0.50, 0.12)
    assert load_factor("shape").values == ("cube", "cylinder", "hex_prism", "cuboid")
    instructions = load_factor("instruction").values
    assert len(instructions) == 3
    assert instructions[0] == baselines()["instruction"]


def test_instructions_name_neither_color_nor_shape():
    words = set(COLORS) | {"cube", "cylinder", "prism", "cuboid", "hex"}
    for text in load_factor("instruction").values:
        # "yellow" names the target box, not the manipulated object.
        assert not (set(text.split()) - {"yellow"}) & words, text


def test_validate_names_bad_value_and_allowed_values():
    with pytest.raises(
        ValueError, match=r"^unknown shape 'sphere'; allowed: cube, cylinder, hex_prism, cuboid$"
    ):
        load_factor("shape").validate("sphere")
    with pytest.raises(ValueError, match=r"camera_pose 'orbit'; allowed: original, orbit_r0_0"):
        load_factor("camera_pose").validate("orbit")
    with pytest.raises(ValueError, match=r"unknown color 'grey'; allowed: aliceblue.*'gray'"):
        load_factor("color").validate("grey")


def test_load_factor_unknown_lists_valid_names():
    with pytest.raises(ValueError, match=r"unknown factor 'colour'; valid factors: color, camera_"):
        load_factor("colour")
