"""Evaluation: running episodes, the statistics, the reports and the verification of result bundles."""

from roboview import tasks as _tasks  # noqa: F401  (registers the tasks: every room above them reads them)
