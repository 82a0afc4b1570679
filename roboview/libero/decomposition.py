"""LIBERO-plus's camera and sensor-noise dimensions as decompositions' designs: the `liberoplus` task's analysis (`Task.analyses`),
which the statistics room computes (roboview.eval.statistics.decompose) and the report prints
(roboview.eval.reporting.decomposition) without importing this wing.

The camera is LIBERO-plus's five sub-factors (azimuth, elevation, scale, rotation z, rotation y; roboview.libero.plus),
each an integer episode column with its no-change value. Its number is over LIBERO-plus's own variants (its four
splits), totalled as LIBERO-plus's README totals it (every variant episode alike) and as vla-eval's results average it
(each suite's rate, then the four suites' mean). The kinds tested against the no-change view are the five single
changes and LIBERO-plus's two two-change kinds; the dose–responses are over |azimuth| (degrees, the shorter way round)
and scale (percent above 100). The instruction is LIBERO's own or LIBERO-plus's suffixed one, which names the view.

The noise is LIBERO-plus's five corruption types (roboview.libero.noise), each a sub-factor whose value is its severity
1–10 (0: none), and `noise_wrist`. Its number is over LIBERO-plus's own variants (agentview corrupted, the wrist camera
clean); the kinds are the five types, and each again with the wrist camera corrupted too; the dose–responses are over
each type's severity; the twins are every variant with the same noise on the wrist camera.
"""

from __future__ import annotations

from roboview.libero import noise
from roboview.libero.plus import LIBERO_PLUS_SPLITS, NO_CHANGE, SHORT, SPLITS, SUB_FACTORS, SUITES, TASK
from roboview.tasks.decomposition import Decomposition, SubFactor, Twin

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
    splits=SPLITS,
)

NOISE = Decomposition(
    key="liberoplus_noise",
    title="LIBERO-plus's sensor-noise dimension, taken apart",
    task=TASK,
    name="noise",
    sub_factors=(
        *(
            SubFactor(f, noise.SHORT[f], 0, 0, "severity levels", f"{noise.SHORT[f]} severity (1–10)")
            for f in noise.NOISE_FACTORS
        ),
        SubFactor(noise.WRIST_FACTOR, "wrist camera too", 0),
    ),
    kinds=(
        *((f,) for f in noise.NOISE_FACTORS),
        *((f, noise.WRIST_FACTOR) for f in noise.NOISE_FACTORS),
    ),
    variant_splits=noise.LIBERO_PLUS_SPLITS,
    group_column="liberoplus_task",
    groups=SUITES,
    groups_word="suites",
    source="LIBERO-plus",
    micro=("liberoplus", "as LIBERO-plus totals it"),
    macro=("vla_eval", "as vla-eval averages it"),
    instruction_column="liberoplus_instruction",
    instructions=(
        (
            "liberoplus",
            "LIBERO-plus's own (it names the noise code: every value also changes the instruction)",
        ),
        ("libero", "LIBERO's own, whatever the noise (only the frames change)"),
    ),
    splits=noise.SPLITS,
    twin=Twin(
        noise.WRIST_FACTOR,
        "on both cameras",
        "the same noise on the wrist camera too (LIBERO-plus leaves it clean, so a policy that reads it keeps a clean "
        "view)",
    ),
    figure_name="analysis_liberoplus_noise_dose_response.png",
)
