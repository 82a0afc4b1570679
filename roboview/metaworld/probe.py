"""The fairness gate's probe in Meta-World's scenes (the world's `probe`): the task's object judged in `corner2`."""

from __future__ import annotations

from roboview.metaworld.factors import VISIBLE_GROUPS
from roboview.tasks.fairness import ObjectProbe


class MetaWorldFairnessProbe(ObjectProbe):
    """The gate in Meta-World's scenes: the task's object (`roboview.metaworld.task.OBJECTS`) in corner2, as
    gymnasium's renderer draws it (geom groups 0–2) and LeRobot flips it."""

    geom_groups = VISIBLE_GROUPS
