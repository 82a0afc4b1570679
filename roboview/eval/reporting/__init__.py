"""Reporting: report.md (`markdown`), report.html (`html`) and the plots, rendered from the metrics
that `roboview.eval.statistics` computes; the tables both pages print are declared once (`tables`)."""
