"""What a set of study results may claim, in words: status labels, the verdict, the exit policy.

The status of each study comes from :mod:`common.result`; this module only words it, the
same way on the terminal, in the report's table of contents, its summary and results.json.
"every check passed" is said only when :func:`common.result.exit_code` is 0: every study
ran, passed, and left nothing out.
"""

from __future__ import annotations

from typing import Sequence

from common.result import EXIT_FAILED, EXIT_PASSED, Status, StudyResult, exit_code

__all__ = ["EXIT_POLICY", "status_label", "verdict_sentence", "not_covered_lines"]

#: The exit-code policy, as printed at the end of every subcommand's --help and in docs/report.md.
EXIT_POLICY = """exit codes:
  0  every check passed and nothing was left out
  1  a check failed (a tolerance not met) or a study raised an error
  2  bad input (unknown material, mesh, state or study key; unreadable mesh; unwritable
     destination), refused before any work
  3  incomplete: a target missed, a study not run (not selected by --only, a stack not
     installed) or a partial run (quick sizes, a check that could not be measured);
     --allow-incomplete turns 3 into 0 (1 and 2 stay)
  130  interrupted (Ctrl-C); `all` keeps the partial report and leaves reports/latest alone
"""


def status_label(result: StudyResult) -> str:
    """One word or two for a table: 'passed' only for a complete pass."""
    if result.status is Status.PASSED:
        return "passed (partial)" if result.partial else "passed"
    return result.status.value.upper()


def not_covered_lines(results: Sequence[StudyResult]) -> list:
    """'<title>: <what was left out>' for every study that left something out or did not run."""
    lines = []
    for r in results:
        if r.status is Status.NOT_RUN:
            lines.append(f"{r.title}: not run: {r.reason}")
        lines += [f"{r.title}: {item}" for item in r.not_covered]
        lines += [
            f"{r.title}: not measured: {c.name}" + (f" ({c.note})" if c.note else "")
            for c in r.unmeasured
        ]
    return lines


def verdict_sentence(results: Sequence[StudyResult]) -> str:
    """The summary's first line; 'every check passed' only for exit code 0."""
    if not results:
        return "Verdict: nothing ran."
    if exit_code(results) == EXIT_PASSED:
        return f"Verdict: every check passed ({len(results)} studies, all run completely)."
    count = lambda *s: sum(r.status in s for r in results)  # noqa: E731
    parts = []
    for n, what in (
        (count(Status.FAILED), "FAILED"),
        (count(Status.ERROR), "raised an ERROR"),
        (count(Status.TARGET_MISSED), "missed a target"),
        (count(Status.NOT_RUN), "NOT RUN"),
    ):
        if n:
            parts.append(f"{n} {'study' if n == 1 else 'studies'} {what}")
    partial = sum(r.status is Status.PASSED and r.partial for r in results)
    if partial:
        parts.append(f"{partial} passed only partially (see what was not covered)")
    passed = sum(r.complete_pass for r in results)
    word = "FAILED" if exit_code(results) == EXIT_FAILED else "INCOMPLETE"
    return (
        f"Verdict: {word}: {'; '.join(parts)}; {passed} of {len(results)} studies passed "
        "completely."
    )
