"""The `liberoplus` task (``RoboView/LiberoPlus-v0``): LIBERO's scenes with agentview where LIBERO-plus puts it.

The same scenes, tasks, init states, control, success and step budgets as the `libero` task (roboview.libero.task),
with one difference: agentview always takes LIBERO-plus's pose arithmetic (roboview.libero.plus), also when no
sub-factor is set. Its baseline is therefore LIBERO-plus's own no-change view, LIBERO's agentview pose rounded to 4
decimals, which every camera variant is paired against.

**Contexts**: `liberoplus_task` (one of the 40 tasks, `<suite>/<task id>`), `liberoplus_init_state` (LIBERO-plus runs
init state 0; a repeat runs the next init state, as in the `libero` task) and `liberoplus_instruction`:

- `libero` (default): the policy gets LIBERO's own instruction of the task, whatever the view. Only the camera
  changes across the values of a block.
- `liberoplus`: the instruction LIBERO-plus sends, built from the variant's file name ("… on the plate view 346 15 100
  0 0 initstate 0"). Its numbers are comparable with LIBERO-plus's published ones, and the isolation certificate
  names the instruction as a second change of every value.

**Visual factors**: LIBERO-plus's five camera sub-factors (`view_*`, roboview.libero.view), its sensor noise
(`noise_*`), its light and background scenes (`scene_light`, `scene_background`, roboview.libero.plus_scene_world) and
the `libero` task's own (color, lighting…), applied the same way, with LIBERO's world's baseline labels (color
`original`: the object's own texture).
"""

from __future__ import annotations

from dataclasses import replace

from roboview.libero import noise, plus_scenes
from roboview.libero.decomposition import CAMERA, NOISE
from roboview.libero.plus import (
    LIBERO_PLUS_SPLITS,
    SHORT,
    SUB_FACTORS,
    TASK,
    View,
    instruction_of,
    variant_name,
)
from roboview.libero.suites import SUITES
from roboview.libero.task import (
    BASELINE_LABELS,
    LIBERO_MAX_STEPS,
    N_INIT_STATES,
    LiberoTaskEnv,
    LiberoTaskExpert,
)
from roboview.tasks.base import Task, register_preset, register_task
from roboview.variation.factors import Factor, register_baseline_labels, register_factor
from roboview.variation.instances import SuiteConfig

INSTRUCTION_MODES = ("libero", "liberoplus")
# LIBERO's world: its baselines are LIBERO's own look (color `original`), as in the `libero` task.
register_baseline_labels(TASK, BASELINE_LABELS)

LIBEROPLUS_TASK = register_factor(
    Factor(
        name="liberoplus_task",
        kind="context",
        task=TASK,
        values=tuple(f"{suite}/{i}" for suite in SUITES for i in range(10)),
        baseline="libero_spatial/0",
        doc="One of LIBERO's 40 evaluation tasks, <suite>/<task id>, whose camera variants LIBERO-plus defines.",
        title="LIBERO task",
    )
)
LIBEROPLUS_INIT_STATE = register_factor(
    Factor(
        name="liberoplus_init_state",
        kind="context",
        task=TASK,
        values=tuple(str(i) for i in range(N_INIT_STATES)),
        baseline="0",
        doc="Which of the task's 50 LIBERO init states the episode starts from (LIBERO-plus runs 0).",
        title="Init state",
    )
)
LIBEROPLUS_INSTRUCTION = register_factor(
    Factor(
        name="liberoplus_instruction",
        kind="context",
        task=TASK,
        values=INSTRUCTION_MODES,
        baseline="libero",
        doc=(
            "The instruction the policy gets: LIBERO's own (libero), or LIBERO-plus's, which names the view "
            "(liberoplus: the instruction then changes with every value, and the isolation certificate says so)."
        ),
        title="Instruction",
        alters=("instruction",),
    )
)


class LiberoPlusTaskEnv(LiberoTaskEnv):
    """The `liberoplus` task's env: the `libero` task's, agentview always at LIBERO-plus's pose."""

    task = TASK
    task_factor = "liberoplus_task"
    init_factor = "liberoplus_init_state"
    # agentview always at LIBERO-plus's pose, its no-change view (LIBERO's pose rounded) included.
    always_applied = SUB_FACTORS

    def baseline_instance(self):
        return baseline_liberoplus_instance()

    def instruction_of(self, instance, world) -> str:
        if instance.get("liberoplus_instruction") == "libero":
            return world.task.language
        values = instance.factor_values
        scene = plus_scenes.scene_set(values)
        if scene:  # a light or background variant's file name (`<task>_light_<n>`)
            task = instance.get(self.task_factor)
            return instruction_of(plus_scenes.variant_of(task, *scene).name)
        name = variant_name(world.task.name, View.of(values))
        code = noise.noise_code(values)
        return instruction_of(f"{name}_noise_{code}" if code else name)


def baseline_liberoplus_instance(task: str = LIBEROPLUS_TASK.baseline, init_state: str = "0"):
    """Every visual factor at its baseline (LIBERO-plus's no-change view) on `task` from `init_state`."""
    from roboview.variation.factors import baselines
    from roboview.variation.instances import TaskInstance

    values = baselines(TASK) | {"liberoplus_task": task, "liberoplus_init_state": init_state}
    return TaskInstance(
        split="baseline", varied=("view_azimuth",), factors=values, context_subspace="base", task=TASK
    )


def changes_of(values: dict[str, str]) -> str:
    """The sub-factors a view changes, in words ("azimuth + elevation"; "none")."""
    changed = View.of(values).changes
    return " + ".join(SHORT[f] for f in changed) or "none"


register_task(
    Task(
        name=TASK,
        gym_id="RoboView/LiberoPlus-v0",
        env="roboview.libero.plus_task:LiberoPlusTaskEnv",
        success="LIBERO's own goal predicate for the task (check_success) holds",
        timeout_reason="LIBERO's goal not reached",
        expert="roboview.libero.task:LiberoTaskExpert",
        small_contexts=(("liberoplus_task", ("libero_object/0",)), ("liberoplus_init_state", ("0",))),
        max_episode_steps=LIBERO_MAX_STEPS,
        steps_per_context=True,
        seed_randomizes="fixture placement (cabinets, stoves…) in some scenes, nothing in others",
        repeat_factor="liberoplus_init_state",
        world_factor="liberoplus_task",
        analyses=(CAMERA, NOISE),
    )
)

# LIBERO-plus's camera dimension (roboview.libero.plus; docs/liberoplus.md), on the `liberoplus` task: its 1,599
# variants of the 40 tasks from init state 0, beside their single-change parts and a no-change view per task.
# `liberoplus_camera_suffixed`: the same, the policy told LIBERO-plus's instruction (which names the view).
# `liberoplus_camera_tiny`: one task (libero_object/2), one variant of each kind and its parts: 8 instances.
LIBERO_PLUS = SuiteConfig(
    preset="liberoplus_camera",
    tasks=("liberoplus",),
    union_mode="dedupe",
    splits=(
        "view_azimuth",
        "view_scale",
        "view_azimuth_x_view_elevation",
        "view_rotz_x_view_roty",
        "view_azimuth_parts",
        "view_elevation",
        "view_rotz",
        "view_roty",
    ),
    factorial_colors=(),
    value_subsets=(("liberoplus_init_state", ("0",)),),
    generator="roboview.libero.plus:camera_suite",
    # LIBERO-plus's own variants (and each task's no-change view) are kept whatever the gate says: its number is over
    # its whole set. The single-change parts RoboView adds stay gated.
    ungated_splits=LIBERO_PLUS_SPLITS,
)
register_preset(LIBERO_PLUS)
register_preset(
    replace(
        LIBERO_PLUS,
        preset="liberoplus_camera_suffixed",
        value_subsets=(*LIBERO_PLUS.value_subsets, ("liberoplus_instruction", ("liberoplus",))),
    )
)
# One suite's share (what a checkpoint fine-tuned on that suite alone is run on, as LIBERO-plus and vla-eval run
# one suite at a time): `liberoplus_camera_spatial`, `_object`, `_goal`, `_10`.
for _suite in ("spatial", "object", "goal", "10"):
    register_preset(
        replace(
            LIBERO_PLUS,
            preset=f"liberoplus_camera_{_suite}",
            value_subsets=(
                *LIBERO_PLUS.value_subsets,
                ("liberoplus_task", tuple(f"libero_{_suite}/{i}" for i in range(10))),
            ),
        )
    )
register_preset(
    replace(
        LIBERO_PLUS,
        preset="liberoplus_camera_tiny",
        value_subsets=(
            *LIBERO_PLUS.value_subsets,
            ("liberoplus_task", ("libero_object/2",)),
            ("view_azimuth", ("31",)),
            ("view_scale", ("125",)),
            ("view_rotz", ("6",)),
            ("view_roty", ("2",)),
        ),
    )
)

# LIBERO-plus's sensor-noise dimension (roboview.libero.noise; docs/liberoplus.md), on the `liberoplus` task: its 1,601
# variants of the 40 tasks (agentview corrupted, init state 0), the severities it does not run of each type on each task
# (the ladder), every one of them again on both cameras, and a no-change view per task.
# `liberoplus_noise_suffixed`: the same, the policy told LIBERO-plus's instruction (which names the noise code).
# `liberoplus_noise_object` (and `_spatial`, `_goal`, `_10`): one suite's share.
# `liberoplus_noise_tiny`: libero_object/2, one severity of each type and a ladder one of fog: 13 instances.
LIBERO_PLUS_NOISE = SuiteConfig(
    preset="liberoplus_noise",
    tasks=("liberoplus",),
    union_mode="dedupe",
    splits=noise.SPLITS,
    factorial_colors=(),
    value_subsets=(("liberoplus_init_state", ("0",)),),
    generator="roboview.libero.noise:noise_suite",
    # LIBERO-plus's own variants (and each task's no-change view) are kept whatever the gate says.
    ungated_splits=noise.LIBERO_PLUS_SPLITS,
)
register_preset(LIBERO_PLUS_NOISE)
register_preset(
    replace(
        LIBERO_PLUS_NOISE,
        preset="liberoplus_noise_suffixed",
        value_subsets=(*LIBERO_PLUS_NOISE.value_subsets, ("liberoplus_instruction", ("liberoplus",))),
    )
)
for _suite in ("spatial", "object", "goal", "10"):
    register_preset(
        replace(
            LIBERO_PLUS_NOISE,
            preset=f"liberoplus_noise_{_suite}",
            value_subsets=(
                *LIBERO_PLUS_NOISE.value_subsets,
                ("liberoplus_task", tuple(f"libero_{_suite}/{i}" for i in range(10))),
            ),
        )
    )
register_preset(
    replace(
        LIBERO_PLUS_NOISE,
        preset="liberoplus_noise_tiny",
        value_subsets=(
            *LIBERO_PLUS_NOISE.value_subsets,
            ("liberoplus_task", ("libero_object/2",)),
            ("noise_motion_blur", ("3",)),
            ("noise_gaussian_blur", ("2",)),
            ("noise_zoom_blur", ("4",)),
            ("noise_fog", ("1", "3")),  # 1: a severity LIBERO-plus does not run on this task (the ladder)
            ("noise_glass_blur", ("5",)),
        ),
    )
)

# LIBERO-plus's light and background dimensions (roboview.libero.plus_scenes, plus_scene_world; docs/liberoplus.md): per
# task, its variants (LIBERO's arena built from LIBERO-plus's scene file and styles, from its asset folder,
# --liberoplus.assets) beside the no-change view, LIBERO's own scene. The presets check that folder for the files of
# their variants before any work. `_tiny`: one task's variants (libero_object/2).
for _dimension, _factor in plus_scenes.FACTOR.items():
    _scenes = SuiteConfig(
        preset=f"liberoplus_{_dimension}",
        tasks=("liberoplus",),
        union_mode="dedupe",
        splits=(_factor,),
        factorial_colors=(),
        value_subsets=(("liberoplus_init_state", ("0",)),),
        generator="roboview.libero.plus_scenes:scene_suite",
        # LIBERO-plus's own variants (and each task's no-change view) are kept whatever the gate says.
        ungated_splits=(_factor,),
    )
    register_preset(_scenes)
    register_preset(
        replace(
            _scenes,
            preset=f"liberoplus_{_dimension}_tiny",
            value_subsets=(*_scenes.value_subsets, ("liberoplus_task", ("libero_object/2",))),
        )
    )

__all__ = ["SUB_FACTORS", "LiberoPlusTaskEnv", "LiberoTaskExpert", "baseline_liberoplus_instance"]
