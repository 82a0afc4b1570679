"""Baselines named for what they are (`World.baseline_labels`, roboview.variation.factors.baseline_of): in LIBERO's
and Meta-World's scenes the color baseline is the object's own look, `original`, and red is a red re-skin; RoboView's
own scene keeps red, and every id of its presets (tests/variation/test_stable_ids.py). A benchmark written before the
label (format 4, `red` stored for LIBERO's baseline) still loads and verifies, read as its build meant it."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from roboview.benchmark import format as bio
from roboview.eval.reporting.plots import category_stats
from roboview.eval.statistics.compare import all_baseline
from roboview.libero.plus_task import LiberoPlusTaskEnv, baseline_liberoplus_instance
from roboview.libero.task import baseline_libero_instance
from roboview.metaworld.task import baseline_metaworld_instance
from roboview.tasks import load_preset
from roboview.tasks.env import baseline_instance
from roboview.tasks.world import load_world
from roboview.variation.colors import get_color
from roboview.variation.factors import baseline_of, baselines, load_factor, record_columns, swept_values
from roboview.variation.instances import SuiteConfig, TaskInstance, generate_suite

pytestmark = pytest.mark.fast


def libero_appliers(values: dict, task: str = "libero", always: tuple[str, ...] = ()) -> list:
    """LIBERO's appliers of `values` (its world's table), as its envs make them at every reset."""
    return load_world("libero").make_appliers(values, task, always)


def metaworld_appliers(values: dict) -> list:
    return load_world("metaworld").make_appliers(values, "metaworld")


def test_each_world_names_its_color_baseline():
    assert load_world("libero").baseline_labels == {"color": "original"}
    assert load_world("metaworld").baseline_labels == {"color": "original"}
    assert dict(load_world("roboview").baseline_labels) == {}
    for instance in (
        baseline_libero_instance(),
        baseline_liberoplus_instance(),
        baseline_metaworld_instance(),
    ):
        assert instance.get("color") == "original", instance.task
    for task in ("pick_place", "push"):
        assert baseline_instance(task).get("color") == "red" == baselines(task)["color"]
    assert baseline_of("color") == load_factor("color").baseline == "red"  # no task: the registered baseline
    assert (
        baseline_of("camera_pose", "libero") == "original"
    )  # unlabelled factors keep their registered baseline


def test_original_is_a_value_only_where_a_world_labels_it():
    base = dict(baseline_instance("pick_place").factors)
    with pytest.raises(ValueError, match="unknown color 'original'"):
        TaskInstance("color", ("color",), base | {"color": "original"}, "base")
    with pytest.raises(ValueError, match="unknown color 'original'"):
        SuiteConfig(value_subsets=(("color", ("original", "red")),))
    # A baseline that is no swept value (camera_pose's `original`) stays out of a subset, in every task.
    with pytest.raises(
        ValueError, match=r"\['original'\] are not swept values of camera_pose in the libero task"
    ):
        SuiteConfig(tasks=("libero",), value_subsets=(("camera_pose", ("original",)),))
    libero = dict(baseline_libero_instance().factors)
    red = TaskInstance("libero_color", ("color",), libero | {"color": "red"}, "base", task="libero")
    assert red.instance_id != baseline_libero_instance().instance_id
    assert load_factor("color").is_valid("original", "metaworld") and not load_factor("color").is_valid(
        "original"
    )
    colors = swept_values("color", "libero")
    assert colors[0] == "original" and "red" in colors and len(colors) == len(load_factor("color").values) + 1


def test_the_labelled_presets_sweep_original_and_real_colors():
    for preset, split in (("libero_tiny", "libero_color"), ("metaworld_tiny", "metaworld_color")):
        suite = generate_suite(load_preset(preset))
        assert [i.get("color") for i in suite if i.split == split] == ["original", "blue"], preset
        assert {i.get("color") for i in suite if i.split != split} == {"original"}, preset
    full = [i for i in generate_suite(load_preset("metaworld")) if i.split == "metaworld_color"]
    per_task = {i.get("color") for i in full if i.get("metaworld_task") == "push-v3"}
    assert per_task == set(
        swept_values("color", "metaworld")
    )  # original and the 141 CSS colors, red a re-skin


def test_a_red_instance_is_re_skinned_and_original_is_not():
    from roboview.libero.factors import ObjectColor as LiberoColor
    from roboview.metaworld.factors import ObjectColor as MetaWorldColor

    libero = dict(baseline_libero_instance().factors)
    assert libero_appliers(libero) == []
    [skin] = libero_appliers(libero | {"color": "red"})
    assert isinstance(skin, LiberoColor) and skin.mode == "skin" and tuple(skin.rgb) == (1.0, 0.0, 0.0)
    plus = dict(baseline_liberoplus_instance().factors)
    assert [
        type(a).__name__
        for a in libero_appliers(plus | {"color": "red"}, "liberoplus", LiberoPlusTaskEnv.always_applied)
    ] == [
        "LiberoPlusView",
        "ObjectColor",
    ]
    metaworld = dict(baseline_metaworld_instance().factors)
    assert metaworld_appliers(metaworld) == []
    [skin] = metaworld_appliers(metaworld | {"color": "red"})
    assert isinstance(skin, MetaWorldColor) and tuple(skin.rgb) == (1.0, 0.0, 0.0)


def test_original_records_no_nominal_color_and_the_control_arm_finds_it():
    assert record_columns({"color": "original"}) == {"color_hex": "", "color_rgb": None, "color_lab": None}
    assert record_columns({"color": "red"})["color_hex"] == "#ff0000"
    import pandas as pd

    rows = []
    for instance in generate_suite(load_preset("libero_tiny")) + generate_suite(load_preset("tiny"))[:3]:
        rows += [instance.to_record() | {"repeat": 0, "success": True}]
    base = all_baseline(pd.DataFrame(rows))
    # LIBERO's control arm is its all-`original` instance, RoboView's its all-red one.
    assert sorted(zip(base["task"], base["color"])) == [("libero", "original"), ("pick_place", "red")]
    stats = category_stats(
        {"p": {"original": {"sr": 0.5, "n_episodes": 4}, "blue": {"sr": 1.0, "n_episodes": 2}}}
    )
    assert list(stats) == ["original", "blue"] and stats["original"] == [{"sr": 0.5, "n_episodes": 4}]


def _write(root, instances, fmt: int) -> None:
    """A benchmark folder of `instances` as a build of format `fmt` writes it (no renders, no reference)."""
    fairness = {"cameras": [], "passed": True, "reject_reason": "", "vlm_answer": "", "vlm_analysis": ""}
    by_split: dict[str, list[dict]] = {}
    for instance in instances:
        by_split.setdefault(instance.split, []).append(
            instance.to_record() | {"cameras": [], "fairness": fairness, "preview": None}
        )
    for split, rows in by_split.items():
        bio.write_split(rows, root / "data" / f"{split}.parquet")
    content = bio.write_checksums(root)
    suite = {"preset": "libero_tiny", "tasks": ["libero"]}
    manifest = {
        "format": fmt,
        "status": bio.BUILT,
        "suite": suite,
        "splits": {split: {} for split in by_split},
        "content": content,
        "benchmark_version": bio.benchmark_version("libero_tiny", content, None),
    }
    (root / bio.MANIFEST).write_text(json.dumps(manifest))


def test_a_benchmark_written_before_the_label_reads_as_built(tmp_path):
    """Format 4 stored LIBERO's baseline as `red` (then: the object's own texture). It loads, every row verified
    against its checksums and its published id, and reads as its build meant it: `original`, nothing re-skinned."""
    new = generate_suite(load_preset("libero_tiny"))
    old = [
        replace(i, factors=tuple((k, "red" if (k, v) == ("color", "original") else v) for k, v in i.factors))
        for i in new
    ]
    _write(tmp_path, old, 4)
    bench = bio.load_benchmark(tmp_path)
    items = {i.record["instance_id"]: i for its in bench.splits.values() for i in its}
    assert set(items) == {i.instance_id for i in old}  # the ids it was published with
    for before, now in zip(old, new):
        item = items[before.instance_id]
        assert item.instance == now and item.instance.instance_id == before.instance_id
        assert item.record["color"] == now.get("color") and item.record["value"] == now.value
        assert item.record["color_hex"] == ("" if now.get("color") == "original" else "#0000ff")
        written = item.as_built or item.record
        assert written["color"] == before.get("color")  # what its results rows of then say, still its own
    # Every LIBERO row of the old build but blue wore its own texture: none is re-skinned now.
    skins = {
        i.record["value"]: [type(a).__name__ for a in libero_appliers(dict(i.instance.factors))]
        for i in items.values()
    }
    assert skins == {
        "original": [],
        "blue": ["ObjectColor"],
        "orbit_r1_3": ["OrbitalPose"],
        "dim_left": ["Lighting"],
    }
    # The same suite written now (format 5) stores `original` and reads unchanged.
    _write(tmp_path / "now", new, bio.FORMAT_VERSION)
    now = bio.load_benchmark(tmp_path / "now")
    assert all(i.as_built is None for its in now.splits.values() for i in its)
    rows = {r["value"]: r for r in bio.read_rows(tmp_path / "now" / "data" / "libero_color.parquet")}
    assert rows["original"]["color_rgb"] is None and rows["blue"]["color_rgb"] == [0.0, 0.0, 1.0]
    assert rows["blue"]["color_lab"] == list(get_color("blue").lab) and rows["original"]["color_hex"] == ""
