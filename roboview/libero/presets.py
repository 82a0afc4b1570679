"""LIBERO's suite presets (the `libero` task, roboview.libero.task; docs/libero.md), registered with its task.

Their factors: every visual factor but distractors and object_size; the color baseline is the object's own texture,
`original` (LIBERO's baseline label), and every CSS color, red included, a re-skin.

- `libero_tiny`: one context (libero_object task 0, init state 0) and a few values: 4 instances, for tests and
  `make demo-libero`.
- `libero_small`: one task (libero_object/0) from 10 init states × one or two values of each of the six factors: 80
  instances, a first bias profile of a learned policy that a CPU evaluates in well under an hour (docs/libero.md).
- `libero`: the 40 tasks of the four suites (init state 0) × every value of the six factors (color: `original` and
  the 141 CSS colors), 7,920 instances (a GPU-scale study; docs/libero.md says how to run a share of it). Its color
  split does not pass the fairness gate on every LIBERO object yet (docs/libero.md#build-and-evaluate).
- `libero_camera`: the `libero` preset's three camera splits alone (the 40 tasks, init state 0, every value of
  camera_pose, camera_euler and dist_scale): 1,560 instances, a camera profile the size of LIBERO-plus's camera
  dimension (1,599 variants). Repeats run init states 1, 2, … (docs/libero.md#cost-of-a-libero-profile).
- `libero_object`: the look of one suite, libero_object's 10 tasks (init state 0), in the `libero` preset's color
  (`original` and the seven colors of RoboView's factorial palette), lighting and table-texture splits: 250
  instances, the visual profile of a policy trained on that suite (docs/results/libero_act.md). Repeats run init
  states 1, 2, …, which demos collected from init states 10–49 never saw.
- `libero_scene_text`: the typographic factor (`scene_text`, a card with a word on the table) over the 40 tasks (init
  state 0; repeats run init states 1, 2, …): 280 instances; `libero_scene_text_tiny`: over libero_object's first task
  alone, 7, for tests and demos.

LIBERO-plus's presets are registered with its task (roboview.libero.plus_task).
"""

from __future__ import annotations

from dataclasses import replace

from roboview.tasks.base import register_preset
from roboview.variation.instances import DEFAULT_FACTORIAL_COLORS, SuiteConfig

LIBERO_SPLITS = ("color", "camera_pose", "camera_euler", "dist_scale", "lighting", "table_texture")

LIBERO_TINY = register_preset(
    SuiteConfig(
        preset="libero_tiny",
        tasks=("libero",),
        union_mode="dedupe",
        splits=("color", "camera_pose", "lighting"),
        factorial_colors=(),
        value_subsets=(
            ("color", ("original", "blue")),
            ("camera_pose", ("orbit_r1_3",)),
            ("lighting", ("dim_left",)),
            ("libero_task", ("libero_object/0",)),
            ("init_state", ("0",)),
        ),
    )
)
LIBERO_SMALL = register_preset(
    SuiteConfig(
        preset="libero_small",
        tasks=("libero",),
        union_mode="dedupe",
        splits=LIBERO_SPLITS,
        factorial_colors=(),
        value_subsets=(
            ("color", ("original", "blue", "green")),
            ("camera_pose", ("orbit_r1_3",)),
            ("camera_euler", ("6,0",)),
            ("dist_scale", ("4",)),
            ("lighting", ("dim_left",)),
            ("table_texture", ("checker_dark",)),
            ("libero_task", ("libero_object/0",)),
            ("init_state", tuple(str(i) for i in range(10))),
        ),
    )
)
LIBERO = register_preset(
    SuiteConfig(
        preset="libero",
        tasks=("libero",),
        union_mode="dedupe",
        splits=LIBERO_SPLITS,
        factorial_colors=(),
        value_subsets=(("init_state", ("0",)),),
    )
)
LIBERO_CAMERA = register_preset(
    replace(LIBERO, preset="libero_camera", splits=("camera_pose", "camera_euler", "dist_scale"))
)
LIBERO_OBJECT = register_preset(
    replace(
        LIBERO,
        preset="libero_object",
        splits=("color", "lighting", "table_texture"),
        value_subsets=(
            ("color", ("original", *DEFAULT_FACTORIAL_COLORS)),
            ("libero_task", tuple(f"libero_object/{i}" for i in range(10))),
            ("init_state", ("0",)),
        ),
    )
)
LIBERO_SCENE_TEXT = register_preset(
    replace(
        LIBERO, preset="libero_scene_text", splits=("scene_text",), value_subsets=(("init_state", ("0",)),)
    )
)
register_preset(
    replace(
        LIBERO_SCENE_TEXT,
        preset="libero_scene_text_tiny",
        value_subsets=(("libero_task", ("libero_object/0",)), ("init_state", ("0",))),
    )
)
