"""Named suites over the registered tasks: the paper's, its set-union variant, the extended one, and
small ones for demos and tests whose context values each task declares (`Task.small_contexts`).

    >>> load_preset("tiny").tasks
    ('pick_place',)
"""

from __future__ import annotations

from dataclasses import replace

from roboview.tasks.base import load_task
from roboview.variation.factors import DEFAULT_TASK
from roboview.variation.instances import FACTORIAL_SPLIT, SuiteConfig

PAPER = SuiteConfig()
# The small presets' values of each visual factor. The colors include the vision agent's known
# weaknesses (yellows merge with the box, grays with the table) so the demo's report has a real bias to find.
SMALL_VISUALS = (
    ("color", ("red", "green", "blue", "white", "gold", "yellow", "gray", "dimgray")),
    ("camera_pose", ("orbit_r0_0", "orbit_r1_3", "orbit_r2_6")),
    ("camera_euler", ("-6,-6", "0,0", "6,6")),
    ("dist_scale", ("0", "4", "8")),
)
# Two values of each factor beyond the paper (three lights).
SMALL_EXTENDED_VISUALS = (
    ("lighting", ("dim_left", "default", "bright_front")),
    ("table_texture", ("plain", "checker_dark")),
    ("distractors", ("0", "4")),
    ("object_size", ("0.7", "1.3")),
)
# Beyond the paper (docs/formats.md, "Factors"): the paper's splits plus one per new visual factor.
EXTENDED_SPLITS = (
    "color",
    "camera_pose",
    "camera_euler",
    "dist_scale",
    "lighting",
    "table_texture",
    "distractors",
    "object_size",
    FACTORIAL_SPLIT,
)

PRESETS: dict[str, SuiteConfig] = {}


def register_preset(cfg: SuiteConfig) -> SuiteConfig:
    """Add a suite preset under `cfg.preset` (a name can be registered once)."""
    if cfg.preset in PRESETS:
        raise ValueError(f"preset {cfg.preset!r} is already registered")
    PRESETS[cfg.preset] = cfg
    return cfg


def load_preset(name: str) -> SuiteConfig:
    """Return the registered suite preset `name`; unknown names raise listing the valid ones."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(PRESETS)}") from None


# The paper's suite: 11 x (141 + 21 + 9 + 9) + 7 x 21 = 2,127 instances.
register_preset(PAPER)
# Same splits over the set-union C_Gen: 9 x 180 + 147 = 1,767 instances.
register_preset(replace(PAPER, preset="paper_dedupe", union_mode="dedupe"))
# 3 contexts (G, object left, cylinder) x a few values per visual factor (8 colors, 3 poses, 3 eulers,
# 3 distances) + 2 colors x 3 poses = 57 instances.
register_preset(
    SuiteConfig(
        preset="tiny",
        union_mode="dedupe",
        factorial_colors=("red", "white"),
        value_subsets=(*SMALL_VISUALS, *load_task(DEFAULT_TASK).small_contexts),
    )
)
# Both tasks. pick_place: 11 × (141 + 21 + 9 + 9 + 9 + 8 + 5 + 7) + 147 = 2,446 instances; push over its
# own 4 × 3 = 12 per-subspace contexts (start, zone, shape, instruction; 3 values each): 12 × 209 + 147 = 2,655;
# 5,101 in all.
register_preset(replace(PAPER, preset="extended", splits=EXTENDED_SPLITS, tasks=(DEFAULT_TASK, "push")))
# Both tasks and every factor: the tiny preset's values, two of each new factor's, two push starts × two zones.
register_preset(
    replace(
        PRESETS["tiny"],
        preset="tiny_extended",
        splits=EXTENDED_SPLITS,
        tasks=(DEFAULT_TASK, "push"),
        value_subsets=(
            *PRESETS["tiny"].value_subsets,
            *SMALL_EXTENDED_VISUALS,
            *load_task("push").small_contexts,
        ),
    )
)

# LIBERO's scenes (roboview.libero.task; docs/libero.md). Their factors: every visual factor but distractors and
# object_size; the color baseline is the object's own texture, `original` (LIBERO's baseline label), and every CSS
# color, red included, a re-skin. `libero_tiny`: one context (libero_object task 0, init state 0) and a few values:
# 4 instances, for tests and `make demo-libero`. `libero`: the 40 tasks of the four suites (init state 0) × every
# value of the six factors (color: `original` and the 141 CSS colors), 7,920 instances (a GPU-scale study;
# docs/libero.md says how to run a share of it). Its color split does not pass the fairness gate on every LIBERO
# object yet (docs/libero.md#build-and-evaluate).
LIBERO_SPLITS = ("color", "camera_pose", "camera_euler", "dist_scale", "lighting", "table_texture")
register_preset(
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
# `libero_small`: one task (libero_object/0) from 10 init states × one or two values of each of the six factors:
# 80 instances, a first bias profile of a learned policy that a CPU evaluates in well under an hour (docs/libero.md).
register_preset(
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
register_preset(
    SuiteConfig(
        preset="libero",
        tasks=("libero",),
        union_mode="dedupe",
        splits=LIBERO_SPLITS,
        factorial_colors=(),
        value_subsets=(("init_state", ("0",)),),
    )
)
# `libero_camera`: the `libero` preset's three camera splits alone (the 40 tasks, init state 0, every value of
# camera_pose, camera_euler and dist_scale): 1,560 instances, a camera profile the size of LIBERO-plus's camera
# dimension (1,599 variants). Repeats run init states 1, 2, … (docs/libero.md#cost-of-a-libero-profile).
register_preset(
    replace(PRESETS["libero"], preset="libero_camera", splits=("camera_pose", "camera_euler", "dist_scale"))
)

# Meta-World's scenes (roboview.metaworld.task; docs/metaworld.md): the same six factors as LIBERO's. `metaworld_tiny`:
# push-v3 and a few values, 4 instances, for tests and a first look. `metaworld`: the registered tasks × every value
# of the six factors (repeats run further seeds: further object and goal positions).
register_preset(
    replace(
        PRESETS["libero_tiny"],
        preset="metaworld_tiny",
        tasks=("metaworld",),
        value_subsets=(
            ("color", ("original", "blue")),
            ("camera_pose", ("orbit_r1_3",)),
            ("lighting", ("dim_left",)),
            ("metaworld_task", ("push-v3",)),
        ),
    )
)
register_preset(replace(PRESETS["libero"], preset="metaworld", tasks=("metaworld",), value_subsets=()))
