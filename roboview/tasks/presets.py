"""RoboView's own scene's suite presets: the paper's, its set-union variant, the extended one, and small ones for
demos and tests whose context values each task declares (`Task.small_contexts`).

The registry of presets is `roboview.tasks.base.PRESETS` (`register_preset`, `load_preset`, imported here too); each
world's wing registers its own presets (roboview.libero.presets, roboview.metaworld.presets, and LIBERO-plus's in
roboview.libero.plus_task), and this module, a `roboview.tasks` entry point, registers these.

    >>> load_preset("tiny").tasks
    ('pick_place',)
"""

from __future__ import annotations

from dataclasses import replace

# The two tasks these presets name, registered first.
import roboview.tasks.pick_place  # noqa: F401
import roboview.tasks.push  # noqa: F401
from roboview.tasks.base import PRESETS, load_preset, load_task, register_preset
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

# The paper's suite: 11 x (141 + 21 + 9 + 9) + 7 x 21 = 2,127 instances.
register_preset(PAPER)
# Same splits over the set-union C_Gen: 9 x 180 + 147 = 1,767 instances.
register_preset(replace(PAPER, preset="paper_dedupe", union_mode="dedupe"))
# 3 contexts (G, object left, cylinder) x a few values per visual factor (8 colors, 3 poses, 3 eulers,
# 3 distances) + 2 colors x 3 poses = 57 instances.
TINY = register_preset(
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
        TINY,
        preset="tiny_extended",
        splits=EXTENDED_SPLITS,
        tasks=(DEFAULT_TASK, "push"),
        value_subsets=(
            *TINY.value_subsets,
            *SMALL_EXTENDED_VISUALS,
            *load_task("push").small_contexts,
        ),
    )
)

# The typographic factor alone: a card with a word (`scene_text`), every value over the paper's 11 contexts (77
# instances), and over the tiny preset's 3 (21).
SCENE_TEXT = register_preset(replace(PAPER, preset="scene_text", splits=("scene_text",)))
register_preset(replace(TINY, preset="scene_text_tiny", splits=("scene_text",)))

__all__ = ["EXTENDED_SPLITS", "PAPER", "PRESETS", "SMALL_VISUALS", "TINY", "load_preset", "register_preset"]
