"""LIBERO-plus's sensor-noise dimension: its 1,601 noise variants, the `noise_*` factors and their LIBERO applier, and
the `liberoplus_noise*` presets' instances.

LIBERO-plus names a noise variant `<task>_view_0_0_100_0_0_initstate_0_noise_<code>`: its no-change view (LIBERO's
agentview pose rounded, roboview.libero.plus) from init state 0, the agentview frame of every observation corrupted
by code 1–50 (roboview.libero.corruptions: motion blur, Gaussian blur, zoom blur, fog, glass blur, ten severities
each). The wrist camera stays clean.

Declared as factors, a code is one type's severity: `noise_motion_blur` … `noise_glass_blur` (values 1–10, baseline
0: no noise), and `noise_wrist` (1: the same noise on the wrist camera too; baseline 0, LIBERO-plus's clean wrist
view). Each split of the presets (`noise_suite`) holds, per task:

- `noise_<type>`: LIBERO-plus's own variants of that type (`noise_motion_blur` also holds the no-change view, the
  control arm);
- `noise_<type>_ladder`: the severities of that type LIBERO-plus does not run on the task, so every type it runs
  there has its whole ladder 1–10 (its dose–response);
- `noise_<type>_x_noise_wrist`: every severity again with the wrist camera corrupted too, so the clean wrist view a
  policy may lean on is measured, not assumed away.

The noise of an episode's frame is drawn from a generator seeded by the episode seed and the step
(`corruptions.frame_rng`): every value of a (context, repeat) and both cameras of a step see the same draws, and a
rerun sees them again. LIBERO-plus draws from numpy's global generator instead (motion blur, fog, glass blur), so its
own runs of one variant differ.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

import roboview.libero.view  # noqa: F401  (LIBERO-plus's view_* factors register first, whichever module is imported first)
from roboview.libero.corruptions import SEVERITIES, TYPES, check_imagemagick, code_of, corrupt, frame_rng
from roboview.variation.factors import Factor, register_factor

NOISE_FACTORS = tuple(f"noise_{t}" for t in TYPES)
WRIST_FACTOR = "noise_wrist"
NO_NOISE = "0"
SHORT = dict(zip(NOISE_FACTORS, ("motion blur", "Gaussian blur", "zoom blur", "fog", "glass blur")))
# The isolation certificate's components of the cameras' frames (roboview.eval.running.isolation).
AGENTVIEW_FRAMES, WRIST_FRAMES = "image:agentview", "image:wrist"
_NAME = re.compile(
    r"^(?P<task>.+)_view_(?P<view>\d+_\d+_\d+_\d+_\d+)_initstate_(?P<init>\d+)_noise_(?P<code>\d+)$"
)

for _factor in NOISE_FACTORS:
    register_factor(
        Factor(
            name=_factor,
            kind="visual",
            values=tuple(str(s) for s in range(1, SEVERITIES + 1)),
            baseline=NO_NOISE,
            doc=f"LIBERO-plus's {SHORT[_factor]} on the agentview frames, severity 1–10 (its noise codes "
            f"{code_of(_factor.removeprefix('noise_'), 1)}–{code_of(_factor.removeprefix('noise_'), SEVERITIES)}).",
            title=SHORT[_factor].capitalize(),
            alters=(AGENTVIEW_FRAMES,),
        )
    )
register_factor(
    Factor(
        name=WRIST_FACTOR,
        kind="visual",
        values=("1",),
        baseline="0",
        doc="1: the agentview noise also on the wrist camera's frames (LIBERO-plus leaves the wrist camera clean).",
        title="Noise on the wrist camera too",
        alters=(WRIST_FRAMES,),
    )
)


@dataclass(frozen=True)
class NoiseVariant:
    """One LIBERO-plus noise variant: its file name, LIBERO task (`<suite>/<task id>`) and noise code."""

    name: str
    suite: str
    task_id: int
    code: int

    @property
    def libero_task(self) -> str:
        return f"{self.suite}/{self.task_id}"

    @property
    def factor(self) -> str:
        return NOISE_FACTORS[(self.code - 1) // SEVERITIES]

    @property
    def severity(self) -> int:
        return (self.code - 1) % SEVERITIES + 1


@cache
def noise_variants() -> tuple[NoiseVariant, ...]:
    """LIBERO-plus's noise variants, in its task map's order (each at its no-change view from init state 0)."""
    from roboview.libero.plus import SUITES, task_map
    from roboview.libero.suites import tasks

    out = []
    for suite in SUITES:
        ids = {t.name: t.task_id for t in tasks(suite)}
        for name in task_map()[suite]:
            match = _NAME.match(name) if "_noise_" in name and "_language_" not in name else None
            if match is None:
                continue
            if match["task"] not in ids or match["view"] != "0_0_100_0_0" or match["init"] != "0":
                raise LookupError(
                    f"LIBERO-plus noise variant {name!r} is not at a {suite} task's no-change view"
                )
            out.append(NoiseVariant(name, suite, ids[match["task"]], int(match["code"])))
    return tuple(out)


def counts() -> dict[str, Any]:
    """Noise variants per suite and per type."""
    vs = noise_variants()
    return {
        "total": len(vs),
        "per_suite": dict(Counter(v.suite for v in vs)),
        "per_type": dict(Counter(v.factor for v in vs)),
    }


def noise_code(values: dict[str, str]) -> int:
    """LIBERO-plus's noise code of an instance's `noise_*` values (0: no noise); a one-line ValueError when more than
    one type is set (LIBERO-plus's codes hold one)."""
    set_ = [(f, values[f]) for f in NOISE_FACTORS if values.get(f, NO_NOISE) != NO_NOISE]
    if len(set_) > 1:
        raise ValueError(
            f"noise {dict(set_)}: LIBERO-plus's noise is one type at a time; set one noise_* factor"
        )
    return code_of(set_[0][0].removeprefix("noise_"), int(set_[0][1])) if set_ else 0


@dataclass(frozen=True)
class SensorNoise:
    """The LIBERO applier of the `noise_*` factors: registers the corruption on the cameras whose frames it changes
    (agentview; the wrist camera too with `noise_wrist`), which the env applies to every observation's frames."""

    code: int
    wrist: bool = False

    @classmethod
    def of(cls, values: dict[str, str]) -> SensorNoise:
        """The applier of an instance's `noise_*` values (LIBERO's `World.appliers`)."""
        code = noise_code(values)
        if code == 0:
            raise ValueError(
                f"{WRIST_FACTOR}=1 corrupts the wrist camera with the agentview noise: set a noise_* type"
            )
        return cls(code, values.get(WRIST_FACTOR, "0") == "1")

    def apply(self, world) -> None:
        from roboview.libero.factors import AGENTVIEW, WRIST

        for camera in (AGENTVIEW, WRIST) if self.wrist else (AGENTVIEW,):
            world.image_filters[camera] = self

    def __call__(self, image: np.ndarray, seed: int, step: int) -> np.ndarray:
        """`image` as the policy sees it at `step` of the episode seeded `seed`."""
        return corrupt(image, self.code, frame_rng(seed, step))

    def __str__(self) -> str:
        return f"liberoplus noise {self.code}"


# ---- the benchmark --------------------------------------------------------------------------------------------
LIBERO_PLUS_SPLITS = NOISE_FACTORS  # LIBERO-plus's own variants, one split per type
LADDER_SPLITS = tuple(f"{f}_ladder" for f in NOISE_FACTORS)
WRIST_SPLITS = tuple(f"{f}_x_{WRIST_FACTOR}" for f in NOISE_FACTORS)
SPLITS = LIBERO_PLUS_SPLITS + LADDER_SPLITS + WRIST_SPLITS
BASELINE_SPLIT = NOISE_FACTORS[0]  # holds each context's no-change view (the control arm)


def is_liberoplus_split(split: str) -> bool:
    """Whether a benchmark split (`liberoplus_<split>`) holds LIBERO-plus's own noise variants."""
    return split.removeprefix("liberoplus_") in LIBERO_PLUS_SPLITS


def _views(own: set[tuple[str, int]], subsets: dict) -> dict[str, list[dict[str, str]]]:
    """Each split's noise values for one task running LIBERO-plus's (type, severity) pairs `own`: the no-change view, LIBERO-plus's variants, the ladders of the types it
    runs there, and every one of those again on both cameras."""
    rows: dict[str, list[dict[str, str]]] = {split: [] for split in SPLITS}
    rows[BASELINE_SPLIT].append({})
    for factor in NOISE_FACTORS:
        if not any(f == factor for f, _ in own):
            continue
        for severity in range(1, SEVERITIES + 1):
            if str(severity) not in subsets.get(factor, (str(severity),)):
                continue
            values = {factor: str(severity)}
            rows[factor if (factor, severity) in own else f"{factor}_ladder"].append(values)
            rows[f"{factor}_x_{WRIST_FACTOR}"].append(values | {WRIST_FACTOR: "1"})
    return rows


def noise_suite(cfg) -> list:
    """The `liberoplus_noise*` presets' instances (SuiteConfig.generator): for every task and init state of the preset,
    the splits of the module docstring that `cfg.splits` names. `value_subsets` restricts the tasks
    (`liberoplus_task`), the init states, the instruction mode and the severities of each type. Refused before any
    work where motion blur would run and Wand or ImageMagick is missing."""
    from roboview.libero.plus import split_instances, suite_contexts

    subsets = cfg.subsets
    tasks, _, _ = suite_contexts(subsets)
    own: dict[str, set[tuple[str, int]]] = {}
    for v in noise_variants():
        own.setdefault(v.libero_task, set()).add((v.factor, v.severity))
    by_split: dict[str, list[tuple[str, dict[str, str]]]] = {split: [] for split in SPLITS}
    for task in tasks:
        for split, values in _views(own.get(task, set()), subsets).items():
            by_split[split] += [(task, v) for v in values]
    if any(NOISE_FACTORS[0] in v for s in cfg.splits for _, v in by_split.get(s, ())):
        check_imagemagick()
    out = []
    for split in (s for s in SPLITS if s in cfg.splits):
        varied = tuple(split.removesuffix("_ladder").split("_x_"))
        out += split_instances(split, varied, by_split[split], subsets)
    return out
