"""The fairness gate's probe in LIBERO's scenes (the world's `probe`): the task's object (LIBERO's
`obj_of_interest[0]`) judged in `agentview`, as robosuite renders it."""

from __future__ import annotations

from roboview.libero.factors import VISUAL_GROUP
from roboview.tasks.fairness import ObjectProbe


class LiberoFairnessProbe(ObjectProbe):
    """The gate in LIBERO's scenes: the object in `agentview`; the wrist camera measured, not judged."""

    geom_groups = (VISUAL_GROUP,)
    # robosuite reads its frames bottom row first and the observations turn them 180°: against mujoco.Renderer's
    # top-row-first frames that is a left-right mirror. (Flipping both axes here put the mask on the floor beside a
    # low object: libero_object/1's cream cheese measured the floor's colour whatever its re-skin, ΔE2000 0.6.)
    flip_axes = (1,)
