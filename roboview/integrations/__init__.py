"""RoboView inside other harnesses: LeRobot's lerobot-eval / lerobot-train and vla-eval."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
