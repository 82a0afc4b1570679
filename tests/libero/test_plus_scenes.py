"""LIBERO-plus's light and background dimensions (roboview.libero.plus_scenes): their variants and the scene files
their problem classes load, read from its package; the asset folder, set by --liberoplus.assets or
ROBOVIEW_LIBEROPLUS_ASSETS; and the presets refusing before any work, in one line, when it is unset or lacks a file."""

import os

import pytest

pytestmark = pytest.mark.fast

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("liberoplus", reason="LIBERO-plus not installed (make install-libero)")

from roboview.libero import plus_scenes as ps  # noqa: E402
from roboview.tasks import load_preset  # noqa: E402
from roboview.variation.instances import generate_suite  # noqa: E402

SCENE = "scenes/libero_floor_base_style.xml"  # what every background variant of libero_object/2 loads


def test_variants_and_the_scene_files_their_problem_classes_load():
    light, background = ps.counts("light"), ps.counts("background")
    assert light["total"] == 1142 and light["scene_files"] == 998
    assert light["per_suite"] == {
        "libero_spatial": 292,
        "libero_object": 297,
        "libero_goal": 279,
        "libero_10": 274,
    }
    assert background["total"] == 1076 and background["scene_files"] == 509
    first = ps.scene_variants("light")[0]
    assert first.name.endswith("_place_it_on_the_plate_light_1") and first.libero_task == "libero_spatial/0"
    assert first.problem == "Libero_Tabletop_Manipulation_tabletop_light_sync_modified_0"
    assert first.scene_xml == "scenes/lights/tabletop_light_sync_modified_0.xml"
    # A class that sets only styles loads its base class's scene with them.
    assert ps.scene_of("Libero_Floor_Manipulation_Combined_Floordark_Wallwhite") == (
        SCENE,
        (("floor", "dark"), ("wall", "white")),
    )
    tiny = [v for v in ps.scene_variants("background") if v.libero_task == "libero_object/2"]
    assert {v.scene_xml for v in tiny} == {SCENE} and len({v.styles for v in tiny}) > 1
    with pytest.raises(ValueError, match="allowed: light, background"):
        ps.scene_variants("noise")


def test_a_preset_refuses_in_one_line_without_the_folder(monkeypatch, tmp_path):
    monkeypatch.setenv(ps.ASSETS_ENV, "")  # unset (and restored after the test)
    with pytest.raises(ps.LiberoPlusAssetsMissing) as err:
        generate_suite(load_preset("liberoplus_light_tiny"))
    message = str(err.value)
    assert "\n" not in message and "light variants load 32 scene files" in message and "(not set;" in message
    assert "missing: scenes/lights/" in message and "and 29 more" in message
    assert "huggingface.co/datasets/Sylvest/LIBERO-plus" in message
    assert message.endswith("--liberoplus.assets=DIR (or ROBOVIEW_LIBEROPLUS_ASSETS=DIR)")
    monkeypatch.setenv(ps.ASSETS_ENV, str(tmp_path / "nowhere"))
    with pytest.raises(
        ps.LiberoPlusAssetsMissing, match=r"nowhere is no folder; missing: scenes/libero_floor"
    ):
        generate_suite(load_preset("liberoplus_background_tiny"))


def _scene(folder, scene=SCENE, mesh=True):
    path = folder / scene
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        "<mujoco><asset>"
        '<texture name="texplane" type="2d" file="../textures/original_floor.png"/>'
        '<texture name="tex-wall" type="2d" file="../textures/original_wall.png"/>'
        + ('<mesh name="m" file="../meshes/table.obj"/>' if mesh else "")
        + "</asset></mujoco>"
    )


def test_a_folder_lacking_a_file_is_refused_naming_it(monkeypatch, tmp_path):
    monkeypatch.setenv(ps.ASSETS_ENV, str(tmp_path))
    _scene(tmp_path)
    tiny = [v for v in ps.scene_variants("background") if v.libero_task == "libero_object/2"]
    textures = {f"textures/{ps.style_files()[k][s]}" for v in tiny for k, s in v.styles}
    assert ps.missing_files(tmp_path, {(v.scene_xml, v.styles) for v in tiny}) == sorted(
        textures | {"meshes/table.obj"}
    )
    # The floor's and wall's own textures are replaced by the styles' files, as LIBERO-plus's arenas do.
    assert "textures/original_floor.png" not in ps.missing_files(
        tmp_path, {(v.scene_xml, v.styles) for v in tiny}
    )
    with pytest.raises(ps.LiberoPlusAssetsMissing, match=r"lacks \d+ files its background variants load"):
        generate_suite(load_preset("liberoplus_background_tiny"))
    for name in textures | {"meshes/table.obj"}:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    assert ps.check_assets(tiny) == tmp_path
    # Complete, the folder builds the preset: the task's no-change view, then each variant's problem class.
    built = generate_suite(load_preset("liberoplus_background_tiny"))
    assert [i.value for i in built] == ["original", *(v.problem for v in tiny)]
    assert {i.split for i in built} == {"liberoplus_scene_background"}


def test_the_factors_values_are_the_problem_classes_liberoplus_variants_name(tmp_path):
    from roboview.variation.factors import load_factor

    for dimension, factor in ps.FACTOR.items():
        assert load_factor(factor).values == ps.problems(dimension)
    assert (len(ps.problems("light")), len(ps.problems("background"))) == (998, 921)
    ps.write_values(tmp_path / "values.txt")  # the file the package writes is the one shipped
    assert (tmp_path / "values.txt").read_text() == ps.VALUES_FILE.read_text()


def test_the_flag_sets_the_folder_and_the_verb_refuses_in_one_line(monkeypatch, tmp_path, capsys):
    from roboview.pipelines.build_benchmark import main

    monkeypatch.setenv(ps.ASSETS_ENV, "")  # unset (and restored after the test)
    out = tmp_path / "bench"
    with pytest.raises(SystemExit):
        main([f"--output_dir={out}", "--preset=liberoplus_background_tiny", "--image_size=64"])
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        "error: LIBERO-plus's background variants load 1 scene file from"
    )
    assert not out.exists()
    with pytest.raises(SystemExit):
        main(
            [
                f"--output_dir={out}",
                "--preset=liberoplus_light_tiny",
                f"--liberoplus.assets={tmp_path / 'no'}",
            ]
        )
    assert "--liberoplus.assets=" in capsys.readouterr().err and os.environ[ps.ASSETS_ENV] == ""
    with pytest.raises(SystemExit):
        main([f"--output_dir={out}", "--preset=liberoplus_light_tiny", f"--liberoplus.assets={tmp_path}"])
    assert os.environ[ps.ASSETS_ENV] == str(tmp_path.resolve())
    assert f"asset folder {tmp_path.resolve()} lacks 32 files its light variants" in capsys.readouterr().err
    assert not out.exists()
