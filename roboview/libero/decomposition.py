"""LIBERO-plus's camera dimension as a decomposition's design: the `liberoplus` task's analysis (`Task.analyses`),
which the statistics room computes (roboview.eval.statistics.decompose) and the report prints
(roboview.eval.reporting.decomposition) without importing this wing.

The camera is LIBERO-plus's five sub-factors (azimuth, elevation, scale, rotation z, rotation y; roboview.libero.plus),
each an integer episode column with its no-change value. Its number is over LIBERO-plus's own variants (its four
splits), totalled as LIBERO-plus's README totals it (every variant episode alike) and as vla-eval's results average it
(each suite's rate, then the four suites' mean). The kinds tested against the no-change view are the five single
changes and LIBERO-plus's two two-change kinds; the dose–responses are over |azimuth| (degrees, the shorter way round)
and scale (percent above 100). The instruction is LIBERO's own or LIBERO-plus's suffixed one, which names the view.
"""

from __future__ import annotations

from roboview.libero.plus import LIBERO_PLUS_SPLITS, NO_CHANGE, SHORT, SUB_FACTORS, SUITES, TASK
from roboview.tasks.decomposition import Decomposition, SubFactor

# The dose-response sub-factors: (period of the severity, its unit, the figure's axis label).
DOSE = {
    "view_azimuth": (360, "degrees", "|azimuth| (degrees)"),
    "view_scale": (0, "percent above 100", "scale − 100 (percent)"),
}

CAMERA = Decomposition(
    key="liberoplus_camera",
    title="LIBERO-plus's camera dimension, taken apart",
    task=TASK,
    name="camera",
    sub_factors=tuple(
        SubFactor(f, SHORT[f], b, *DOSE.get(f, (0, "", ""))) for f, b in zip(SUB_FACTORS, NO_CHANGE)
    ),
    kinds=(
        ("view_azimuth",),
        ("view_elevation",),
        ("view_scale",),
        ("view_rotz",),
        ("view_roty",),
        ("view_azimuth", "view_elevation"),
        ("view_rotz", "view_roty"),
    ),
    variant_splits=LIBERO_PLUS_SPLITS,
    group_column="liberoplus_task",
    groups=SUITES,
    groups_word="suites",
    source="LIBERO-plus",
    micro=("liberoplus", "as LIBERO-plus totals it"),
    macro=("vla_eval", "as vla-eval averages it"),
    instruction_column="liberoplus_instruction",
    instructions=(
        ("liberoplus", "LIBERO-plus's own (it names the view: every value also changes the instruction)"),
        ("libero", "LIBERO's own, whatever the view (only the camera changes)"),
    ),
)
