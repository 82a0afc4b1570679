"""LIBERO-plus's light and background variants built and run from an asset folder (roboview.libero.plus_scene_world).

The real folder (LIBERO-plus's assets.zip) is not on this machine: the tests write a small one in its layout. A light
variant's scene file is LIBERO's floor scene with its two lights dimmed and moved; another is LIBERO's floor scene
unchanged; a background variant loads LIBERO's floor scene with a floor style LIBERO's own table lacks, whose texture
is a small PNG written here. Each runs in the `liberoplus` task beside the task's no-change view, LIBERO's own scene."""

import importlib.util
import os
import shutil
import sys
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("liberoplus", reason="LIBERO-plus not installed (make install-libero)")

from roboview.libero import plus_scenes as ps  # noqa: E402
from roboview.libero.bootstrap import ensure_libero  # noqa: E402
from roboview.tasks import load_preset  # noqa: E402
from roboview.variation.instances import generate_suite  # noqa: E402

TASK = "libero_object/2"
BASE = "scenes/libero_floor_base_style.xml"  # LIBERO's scene of the task; LIBERO-plus's folder holds a copy
DIMMED = "Libero_Floor_Manipulation_floor_light_sync_modified_412"  # its light variant _light_2
SAME = "Libero_Floor_Manipulation_floor_light_sync_modified_42"  # _light_10: written as LIBERO's scene, unchanged
FABRIC = "Libero_Floor_Manipulation_FloorFabricTarpPlastic001_AO_3K"  # _table_1: a floor style LIBERO lacks
LIGHT = ("0.3 0.25 0.2", "0.5 -1 3")  # the dimmed lights' diffuse and position


def libero_assets() -> Path:
    ensure_libero()
    return Path(importlib.util.find_spec("libero").submodule_search_locations[0]) / "libero" / "assets"


def write_scene(folder: Path, scene: str, light: tuple[str, str] | None = None) -> None:
    """LIBERO's floor scene at `scene` in `folder`, the files it names under `folder` as in LIBERO's assets (linked),
    its paths relative to its own folder as MuJoCo resolves them; `light`: both lights' diffuse and position."""
    libero, path = libero_assets(), folder / scene
    root = ET.parse(libero / BASE).getroot()
    for node in root.iter():
        if node.get("file"):
            source = Path(os.path.normpath(libero / "scenes" / node.get("file")))
            target = folder / source.relative_to(libero)
            target.parent.mkdir(parents=True, exist_ok=True)
            if not target.exists():
                target.symlink_to(source)
            node.set("file", str(Path("../" * (len(Path(scene).parts) - 1)) / source.relative_to(libero)))
    for node in root.iter("light"):
        if light is not None:
            node.set("diffuse", light[0])
            node.set("pos", light[1])
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path)


def write_styles(folder: Path) -> dict[str, np.ndarray]:
    """The style textures the variants name: LIBERO's file where it ships one (linked), else a small PNG written
    here; returns the written ones' pixels by file name."""
    from PIL import Image

    written = {}
    for problem in (DIMMED, SAME, FABRIC):
        for kind, style in ps.scene_of(problem)[1]:
            name = ps.style_files()[kind][style]
            target, source = folder / "textures" / name, libero_assets() / "textures" / name
            if target.exists():
                continue
            if source.is_file():
                target.symlink_to(source)
            else:
                pixels = np.zeros((16, 16, 3), np.uint8)
                pixels[::2, :, 0], pixels[1::2, :, 2] = 255, 255  # magenta and blue stripes
                Image.fromarray(pixels).save(target)
                written[name] = pixels
    return written


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("liberoplus_assets")
    write_scene(folder, BASE)
    write_scene(folder, ps.scene_of(DIMMED)[0], LIGHT)
    write_scene(folder, ps.scene_of(SAME)[0])
    write_styles(folder)
    yield folder
    shutil.rmtree(folder)


def suite(dimension: str, problems: tuple[str, ...]) -> list:
    cfg = load_preset(f"liberoplus_{dimension}_tiny")
    subsets = (*cfg.value_subsets, (ps.FACTOR[dimension], problems))
    return generate_suite(replace(cfg, value_subsets=subsets))


def test_the_presets_build_from_the_folder_with_the_no_change_view_as_control(folder, monkeypatch):
    monkeypatch.setenv(ps.ASSETS_ENV, str(folder))
    light = suite("light", (DIMMED, SAME))
    assert [(i.split, i.value) for i in light] == [  # in LIBERO-plus's task map's order (_light_10, _light_2)
        ("liberoplus_scene_light", "original"),
        ("liberoplus_scene_light", SAME),
        ("liberoplus_scene_light", DIMMED),
    ]
    assert all(i.get("liberoplus_task") == TASK and i.get("liberoplus_init_state") == "0" for i in light)
    # Deterministic ids; one seed per context, shared by the variants and their control.
    again = suite("light", (DIMMED, SAME))
    assert [i.instance_id for i in again] == [i.instance_id for i in light]
    assert len({i.instance_id for i in light}) == 3 and len({i.seed for i in light}) == 1
    # The control is the task's no-change view of every liberoplus preset (the camera preset's: the same values).
    camera = [i.factors for i in generate_suite(load_preset("liberoplus_camera_tiny"))]
    assert light[0].factors in camera and light[1].factors not in camera
    background = suite("background", (FABRIC,))
    assert background[0].factors == light[0].factors and background[1].value == FABRIC
    # The factor's values are LIBERO-plus's problem classes; another is refused naming the allowed ones.
    with pytest.raises(ValueError, match=r"unknown scene_light 'Libero_nothing'; allowed: original, Libero_"):
        suite("light", ("Libero_nothing",))


@pytest.fixture(scope="module")
def env():
    from roboview.libero.plus_task import LiberoPlusTaskEnv

    env = LiberoPlusTaskEnv(image_size=96)
    yield env
    env.close()


def run(env, instance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """After the reset to `instance`: the agentview frame the policy gets, and MuJoCo's own render of the live state
    from agentview with its segmentation (geom ids), pixel for pixel aligned."""
    import mujoco

    obs, _ = env.reset(seed=instance.seed, options={"instance": instance})
    with env.libero_world.own_gl(), mujoco.Renderer(env.model, 96, 96) as renderer:
        renderer.update_scene(env.data, camera="agentview")
        rgb = renderer.render()
        renderer.enable_segmentation_rendering()
        renderer.update_scene(env.data, camera="agentview")
        seg = renderer.render()[..., 0]
    return obs["observation.images.agentview"], rgb, seg


def test_a_variant_runs_liberoplus_scene_and_changes_what_it_should(folder, env, monkeypatch):
    monkeypatch.setenv(ps.ASSETS_ENV, str(folder))
    control, same, dimmed = suite("light", (DIMMED, SAME))
    fabric = suite("background", (FABRIC,))[1]
    base, base_rgb, seg = run(env, control)
    assert env.libero_world.arena[0].endswith("/assets/" + BASE)  # LIBERO's own
    # A light variant: the scene file's lights, from the folder; every pixel's light changes.
    frame, _, _ = run(env, dimmed)
    assert env.libero_world.arena[0] == str(folder / ps.scene_of(DIMMED)[0])
    diffuse = np.array([float(x) for x in LIGHT[0].split()])
    assert np.allclose(env.model.light_diffuse[:2], diffuse) and np.allclose(
        env.model.light_pos[:2], [0.5, -1, 3]
    )
    assert np.abs(frame.astype(int) - base).mean() > 10
    assert env.instruction == "pick up the salad dressing and place it in the basket"
    # LIBERO-plus's instruction, built from the variant's file name (`…_light_2`).
    told = replace(dimmed, factors=(*dimmed.factors[:-1], ("liberoplus_instruction", "liberoplus")))
    assert env.instruction_of(told, env.libero_world).endswith("in the basket light 2")
    # LIBERO's scene written as a variant's: the frame is the no-change view's, pixel for pixel.
    frame, _, _ = run(env, same)
    assert np.array_equal(frame, base)
    # A background variant: the floor's texture is the style's file (written here); the object's pixels stay.
    frame, rgb, seg_fabric = run(env, fabric)
    assert np.array_equal(seg_fabric, seg) and not np.array_equal(frame, base)
    diff = np.abs(rgb.astype(int) - base_rgb).mean(axis=2)
    floor = seg == env.model.geom("floor").id
    target = np.isin(seg, env.object_geoms())
    assert (diff[floor] > 0).mean() > 0.99 and target.sum() > 20
    # The object keeps its pixels: all but its edges, where the multisampled floor shows through.
    assert np.median(diff[target]) == 0 and diff[target].mean() < diff[floor].mean() / 5
    # Back to the control: LIBERO's own scene again.
    frame, _, _ = run(env, control)
    assert np.array_equal(frame, base)


def liberoplus_arena(kind: str):
    """LIBERO-plus's own arena class `kind` (its `envs.arenas` module; its `envs` package object made without its
    `__init__`, which needs Wand for the noise dimension: tests/libero/test_plus.py)."""
    ensure_libero()
    name = "liberoplus.liberoplus.envs"
    if name not in sys.modules:
        sys.modules[name] = importlib.util.module_from_spec(importlib.util.find_spec(name))
    from liberoplus.liberoplus.envs.arenas import empty_arena

    return getattr(empty_arena, kind)


def test_the_arena_is_the_one_liberoplus_own_arena_builds(folder, env, monkeypatch):
    monkeypatch.setenv(ps.ASSETS_ENV, str(folder))
    for dimension, problem in (("light", DIMMED), ("background", FABRIC)):
        instance = suite(dimension, (problem,))[1]
        env.reset(seed=instance.seed, options={"instance": instance})
        scene, styles = ps.scene_of(problem)
        theirs = liberoplus_arena("EmptyArena")(
            xml=str(folder / scene), **{f"{kind}_style": style for kind, style in styles}
        )
        theirs.set_origin([0, 0, 0])  # as LIBERO-plus's base domain does next (`_load_model`)
        ours = env.libero_world.inner.model
        for name in ("texplane", "tex-wall", "tex-table"):
            query = f"./texture[@name='{name}']"
            assert ours.asset.find(query).get("file") == theirs.asset.find(query).get("file"), (problem, name)
        lights = [ET.tostring(x) for x in ours.worldbody.iter("light")]
        assert lights[: len(list(theirs.worldbody.iter("light")))] == [
            ET.tostring(x) for x in theirs.worldbody.iter("light")
        ]


def test_a_scene_missing_from_the_folder_is_refused_in_one_line(folder, env, monkeypatch, tmp_path):
    monkeypatch.setenv(ps.ASSETS_ENV, str(folder))
    instance = suite("light", (DIMMED,))[1]
    monkeypatch.setenv(ps.ASSETS_ENV, str(tmp_path))
    with pytest.raises(ps.LiberoPlusAssetsMissing, match=r"lacks 1 files its light variants load") as err:
        env.reset(seed=instance.seed, options={"instance": instance})
    assert "\n" not in str(err.value) and ps.scene_of(DIMMED)[0] in str(err.value)
