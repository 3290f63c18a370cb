"""The verification report: studies run into sections, written as HTML, Markdown and JSON.

    from comparisons.report import run_report
    outcome = run_report("reports", quick=True)
"""

from comparisons.report.runner import RunOutcome, run_report

__all__ = ["run_report", "RunOutcome"]
