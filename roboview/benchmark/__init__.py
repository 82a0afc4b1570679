"""The frozen benchmark: render instances, the fairness gate, the benchmark folder, conformance."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
