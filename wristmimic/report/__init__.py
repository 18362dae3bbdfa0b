"""Reports from evaluation folders: deterministic CSV tables, PNG plots and a ``summary.md``.

>>> from wristmimic.report import build_report
>>> build_report([Path("runs/RUN/eval/paper")], Path("reports/omomo"))
"""

from wristmimic.report.summary import ReportResult, build_report

__all__ = ["ReportResult", "build_report"]
