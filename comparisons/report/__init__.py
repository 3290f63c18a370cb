"""The verification report: study results rendered as HTML, Markdown and JSON.

The studies own their results (:class:`common.result.StudyResult`); this package only
runs the registry (:mod:`comparisons.report.studies`) safely and renders what comes back:

    from comparisons.report import run_report
    from comparisons.report.studies import report_studies
    outcome = run_report("reports", report_studies(), {"materials": ..., "meshes": ..., "states":
    ...}, quick=True)
    outcome.exit_code()  # the written policy: 0, 1 or 3 (130 if interrupted)
"""

from comparisons.report.runner import ReportStudy, RunOutcome, run_report

__all__ = ["run_report", "RunOutcome", "ReportStudy"]
