"""Every policy type RoboView evaluates, and the wire formats of served policies."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
