"""The factor registry: every axis of variation, each declared in one module.

The paper (§5.1) partitions factors into visual perturbation dimensions V, whose bias we measure,
and task context dimensions D, which only diversify the scenarios. Every factor value is a string
exactly as it is stored in the instance records, so the records, the samplers and the env all
speak one vocabulary.

Context factors belong to a task and are declared in its module (`roboview.tasks`). A world's wing may declare
visual factors of its own scenes (LIBERO-plus's `view_*`, roboview.libero.view); the registry, read, holds them too
(roboview.core.registry.discover).

To add a visual factor, write one module like `color.py` — a `Factor` with its values, baseline,
title and an applier that writes a value into the compiled scene — and add it to BUILTIN_MODULES
(or publish it from your own package under the `roboview.factors` entry-point group, so every
worker process registers it too).

    >>> load_factor("dist_scale").values
    ('0', '1', '2', '3', '4', '5', '6', '7', '8')
"""

from __future__ import annotations

import importlib
import importlib.metadata

from roboview.variation.factors.base import (
    BASELINE_LABELS,
    DEFAULT_TASK,
    FACTOR_KINDS,
    FACTORS,
    Factor,
    SceneApplier,
    baseline_of,
    baselines,
    context_factors,
    factor_names,
    load_factor,
    record_columns,
    register_baseline_labels,
    register_factor,
    swept_values,
    unregister_factor,
    visual_factors,
)

# Registry lines: imported in this order, which is the order of the record columns and of the
# appliers at reset (orbital pose before Euler turn before pull-back).
BUILTIN_MODULES = (
    "roboview.variation.factors.color",
    "roboview.variation.factors.camera",
    # Beyond the paper (the `extended` preset): each one module.
    "roboview.variation.factors.lighting",
    "roboview.variation.factors.table_texture",
    "roboview.variation.factors.distractors",
    "roboview.variation.factors.object_size",
    "roboview.variation.factors.scene_text",
)
# Third-party factors: a package lists its factor modules under this entry-point group.
ENTRY_POINT_GROUP = "roboview.factors"
for _module in BUILTIN_MODULES:
    importlib.import_module(_module)
for _entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
    importlib.import_module(_entry.value.split(":")[0])

from roboview.variation.factors.camera import (  # noqa: E402  (after registration)
    CAMERA_POSE_BASELINE,
    DIST_STEP_M,
    EULER_STEPS_DEG,
    N_ORBIT_POSES_PER_RING,
    N_ORBIT_RINGS,
    parse_camera_pose,
    parse_dist_scale,
    parse_euler,
)

__all__ = [
    "BASELINE_LABELS",
    "BUILTIN_MODULES",
    "CAMERA_POSE_BASELINE",
    "DEFAULT_TASK",
    "DIST_STEP_M",
    "EULER_STEPS_DEG",
    "FACTORS",
    "FACTOR_KINDS",
    "N_ORBIT_POSES_PER_RING",
    "N_ORBIT_RINGS",
    "Factor",
    "SceneApplier",
    "baseline_of",
    "baselines",
    "context_factors",
    "factor_names",
    "load_factor",
    "parse_camera_pose",
    "parse_dist_scale",
    "parse_euler",
    "record_columns",
    "register_baseline_labels",
    "register_factor",
    "swept_values",
    "unregister_factor",
    "visual_factors",
]
