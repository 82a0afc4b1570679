"""The fairness gate's probe in LIBERO's scenes (the world's `probe`): the task's object (LIBERO's
`obj_of_interest[0]`) judged in `agentview`, as robosuite renders it."""

from __future__ import annotations

from roboview.libero.factors import VISUAL_GROUP
from roboview.tasks.fairness import ObjectProbe


class LiberoFairnessProbe(ObjectProbe):
    """The gate in LIBERO's scenes: the object in `agentview`; the wrist camera measured, not judged."""

    geom_groups = (VISUAL_GROUP,)
