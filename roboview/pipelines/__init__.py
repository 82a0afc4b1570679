"""The verbs: one module per console script (`roboview-<verb>`), each parsing flags and calling the library."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
