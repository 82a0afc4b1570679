"""Meta-World's suite presets (the `metaworld` task, roboview.metaworld.task; docs/metaworld.md), registered with its
task. Their factors are the six LIBERO's scenes take too (every visual factor but distractors and object_size; the
color baseline is the object's own texture, `original`).

- `metaworld_tiny`: push-v3 and a few values, 4 instances, for tests and a first look.
- `metaworld`: the registered tasks × every value of the six factors (repeats run further seeds: further object and
  goal positions).
"""

from __future__ import annotations

from roboview.tasks.base import register_preset
from roboview.variation.instances import SuiteConfig

METAWORLD_SPLITS = ("color", "camera_pose", "camera_euler", "dist_scale", "lighting", "table_texture")

METAWORLD_TINY = register_preset(
    SuiteConfig(
        preset="metaworld_tiny",
        tasks=("metaworld",),
        union_mode="dedupe",
        splits=("color", "camera_pose", "lighting"),
        factorial_colors=(),
        value_subsets=(
            ("color", ("original", "blue")),
            ("camera_pose", ("orbit_r1_3",)),
            ("lighting", ("dim_left",)),
            ("metaworld_task", ("push-v3",)),
        ),
    )
)
METAWORLD = register_preset(
    SuiteConfig(
        preset="metaworld",
        tasks=("metaworld",),
        union_mode="dedupe",
        splits=METAWORLD_SPLITS,
        factorial_colors=(),
        value_subsets=(),
    )
)
