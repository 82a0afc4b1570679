"""Statistics over episode rows: per-split metrics and their tests, paired comparisons, context
effects, adaptive stopping, rankings and the simulator that validates them.

The public API: `roboview.eval.statistics.metrics.compute_all_metrics` (metrics.json), and for modules that build
statistics of their own `roboview.eval.statistics.tables` (`MetricsConfig` and its random streams, `CellTable`,
`rate_ci95`, `paired_difference_ci95`, `value_order`) and `roboview.eval.statistics.significance` (the tests, `lrt_fields`). The columns the
report pages print are declared once in `roboview.eval.reporting.tables`.
"""
