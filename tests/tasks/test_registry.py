"""The registries are filled by the worlds' wings through the `roboview.tasks` entry points and discovered when read:
a fresh interpreter that imports any wing (or any registering module, or the contract) first ends with the same
tasks, worlds, presets and factors, listed in the same order."""

import json
import subprocess
import sys

import pytest

from roboview.core import registry
from roboview.core.registry import Registry, rank, wing_modules

pytestmark = pytest.mark.fast

# What a process reads from the registries (and gymnasium's), after importing one module first.
READ = """
import importlib, json, sys
importlib.import_module(sys.argv[1])
import gymnasium
from roboview.tasks.base import PRESETS, TASKS
from roboview.tasks.world import WORLDS
from roboview.variation.factors import BASELINE_LABELS, FACTORS, visual_factors
print(json.dumps({
    "tasks": list(TASKS), "worlds": list(WORLDS), "presets": list(PRESETS), "visual": list(visual_factors()),
    "factors": sorted(FACTORS), "labels": sorted(BASELINE_LABELS),
    "gym": sorted(t.gym_id for t in TASKS.values() if t.gym_id in gymnasium.registry),
}))
"""
FIRST = (
    "roboview.tasks",
    "roboview.tasks.world",
    "roboview.tasks.base",
    "roboview.tasks.push",
    "roboview.tasks.presets",
    "roboview.libero",
    "roboview.libero.task",
    "roboview.libero.plus_task",
    "roboview.libero.presets",
    "roboview.libero.view",
    "roboview.libero.plus_scene_world",
    "roboview.metaworld",
    "roboview.metaworld.task",
    "roboview.metaworld.presets",
    "roboview.variation.factors",
)
TASKS = ["pick_place", "push", "libero", "metaworld", "liberoplus"]
WORLDS = ["roboview", "libero", "metaworld"]
PRESETS = [
    *("paper", "paper_dedupe", "tiny", "extended", "tiny_extended", "scene_text", "scene_text_tiny"),
    *("libero_tiny", "libero_small", "libero", "libero_camera", "libero_object"),
    *("libero_scene_text", "libero_scene_text_tiny"),
    *("metaworld_tiny", "metaworld"),
    *(
        "liberoplus_camera",
        "liberoplus_camera_suffixed",
        "liberoplus_camera_spatial",
        "liberoplus_camera_object",
    ),
    *("liberoplus_camera_goal", "liberoplus_camera_10", "liberoplus_camera_tiny"),
    *("liberoplus_noise", "liberoplus_noise_suffixed", "liberoplus_noise_spatial", "liberoplus_noise_object"),
    *("liberoplus_noise_goal", "liberoplus_noise_10", "liberoplus_noise_tiny"),
    *("liberoplus_light", "liberoplus_light_tiny", "liberoplus_background", "liberoplus_background_tiny"),
]
VIEW = ["view_azimuth", "view_elevation", "view_scale", "view_rotz", "view_roty"]
NOISE = [f"noise_{t}" for t in ("motion_blur", "gaussian_blur", "zoom_blur", "fog", "glass_blur", "wrist")]
SCENE = ["scene_light", "scene_background"]


def test_any_module_imported_first_gives_the_same_registries_in_the_same_order():
    procs = {
        first: subprocess.Popen(
            [sys.executable, "-c", READ, first], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for first in FIRST
    }
    got = {}
    for first, proc in procs.items():
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, f"{first} imported first: {err[-1500:]}"
        got[first] = json.loads(out.strip().splitlines()[-1])
    want = got["roboview.tasks"]
    assert want["tasks"] == TASKS and want["worlds"] == WORLDS and want["presets"] == PRESETS
    # RoboView's own visual factors first (the factor registry's modules), then the LIBERO wing's.
    assert want["visual"][:2] == ["color", "camera_pose"] and want["visual"][-13:] == VIEW + NOISE + SCENE
    assert want["labels"] == ["libero", "liberoplus", "metaworld"] and len(want["gym"]) == 5
    different = {first: read for first, read in got.items() if read != want}
    assert not different, different


def test_roboviews_wing_modules_are_its_entry_points_in_order():
    assert wing_modules()[:6] == (
        "roboview.tasks.pick_place",
        "roboview.tasks.push",
        "roboview.tasks.presets",
        "roboview.libero.task",
        "roboview.metaworld.task",
        "roboview.libero.plus_task",
    )


def test_a_registry_lists_entries_by_the_module_they_come_from():
    things: Registry[str] = Registry("thing", origin=lambda module: module)
    things.add("plus", "roboview.libero.plus_task")
    things.add("lib", "roboview.libero")  # the wing's package ranks with its first entry point
    things.add("elsewhere", "my_package.lift")  # no entry point of this interpreter: after them all
    things.add("push", "roboview.tasks.push")
    things.add("presets", "roboview.tasks.presets")
    things.add("contract", "roboview.tasks.world")  # RoboView's contract ranks with its first task
    assert list(things) == ["contract", "push", "presets", "lib", "plus", "elsewhere"]
    assert rank("roboview.libero.presets") == rank("roboview.libero.task") == 3
    with pytest.raises(ValueError, match=r"thing 'push' is already registered"):
        things.add("push", "x")
    things.remove("push")
    assert "push" not in things and len(things) == 5
    # Without an origin: registration order.
    plain: Registry[int] = Registry("n")
    plain.add("b", 1)
    plain.add("a", 2)
    assert list(plain) == ["b", "a"] and dict(plain.registered) == {"b": 1, "a": 2}


def test_an_install_without_roboviews_entry_points_says_how_to_reinstall(monkeypatch):
    monkeypatch.setattr(registry.importlib.metadata, "entry_points", lambda group: [])
    wing_modules.cache_clear()
    try:
        with pytest.raises(
            RuntimeError, match=r"names no `roboview.tasks` entry point.*reinstall it.*make install"
        ):
            wing_modules()
    finally:
        monkeypatch.undo()
        wing_modules.cache_clear()
    assert "roboview.libero.task" in wing_modules()
