"""Statistics over episode rows: per-split metrics and their tests, paired comparisons, context
effects, adaptive stopping, rankings and the simulator that validates them.

The public table API is `eval.statistics.tables` (`split_table`, the columns every page renders) and
`eval.statistics.metrics.compute_all_metrics`.
"""
