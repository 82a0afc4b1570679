"""Scripted-expert demos recorded into LeRobot datasets."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
