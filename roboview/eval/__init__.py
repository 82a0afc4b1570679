"""Evaluation: running episodes, the statistics, the reports and the verification of result bundles."""
