"""RoboView's world, factors, tasks, benchmark format and demos.

Importing the package registers the tasks' gymnasium ids (`RoboView/PickPlace-v0`, `RoboView/Push-v0`), as
gymnasium packages do, so `gymnasium.make("RoboView/PickPlace-v0")` works after `import roboview_data`.
"""

from roboview_data import tasks as _tasks  # noqa: F401  (registers the tasks and their gymnasium ids)
