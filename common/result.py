"""What a study returns: a typed result with a status from a small fixed set.

Every study of :mod:`comparisons` (equivalence, timing, rheometer, liver, ...) returns one
:class:`StudyResult`. The command line prints it and the report renders it; neither decides
a verdict of its own. The status is derived from what the study was held to:

- a **tolerance** (:class:`Check` with ``kind="tolerance"``) that fails makes the study FAILED:
  the numbers are wrong;
- a **target** (``kind="target"``, e.g. a speed ratio) that is missed makes it TARGET_MISSED:
  the numbers are right but the goal was not reached;
- a check that could not be measured (``measured is None``), or anything the run left out
  (``not_covered``: quick sizes, a stack not installed, a study skipped by ``--only``),
  makes the result *partial*: it may still be PASSED for what it checked, but a summary must
  not call it complete;
- NOT_RUN and ERROR are built explicitly, with the reason.

Exit codes follow the worst status (:func:`exit_code`): 0 passed and complete, 1 failed or
error, 3 a target missed, a study not run or a partial run.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Mapping, Optional, Sequence, Tuple

from common.blocks import Block

__all__ = [
    "Status",
    "Check",
    "StudyResult",
    "status_from_checks",
    "worst_status",
    "exit_code",
    "EXIT_PASSED",
    "EXIT_FAILED",
    "EXIT_INPUT",
    "EXIT_INCOMPLETE",
]

EXIT_PASSED = 0
EXIT_FAILED = 1
EXIT_INPUT = 2  # bad input, refused before any work (common.options.InputError)
EXIT_INCOMPLETE = 3  # a target missed, a study not run, or a partial run


class Status(str, enum.Enum):
    """The fixed set of outcomes, in increasing order of severity for a summary."""

    PASSED = "passed"
    NOT_RUN = "not run"
    TARGET_MISSED = "target missed"
    FAILED = "failed"
    ERROR = "error"


_SEVERITY = {
    Status.PASSED: 0,
    Status.NOT_RUN: 1,
    Status.TARGET_MISSED: 2,
    Status.FAILED: 3,
    Status.ERROR: 4,
}


@dataclass(frozen=True)
class Check:
    """One number a study was held to.

    name: what was measured, e.g. "force relative error, NeoHookean on cube-small, random".
    measured: the figure, or None when this run could not measure it (``note`` says why).
    limit: the tolerance or the target; relation "<=" (measured must not exceed it) or ">=".
    kind: "tolerance" (failing it is a wrong result) or "target" (missing it is a goal not met).
    """

    name: str
    measured: Optional[float]
    limit: float
    relation: str = "<="
    kind: str = "tolerance"
    note: str = ""

    def __post_init__(self) -> None:
        if self.relation not in ("<=", ">="):
            raise ValueError(
                f"Check {self.name!r}: relation must be '<=' or '>=', not {self.relation!r}"
            )
        if self.kind not in ("tolerance", "target"):
            raise ValueError(
                f"Check {self.name!r}: kind must be 'tolerance' or 'target', not {self.kind!r}"
            )

    @property
    def passed(self) -> Optional[bool]:
        """True or False once measured; None when not measured. NaN never passes."""
        if self.measured is None:
            return None
        m = float(self.measured)
        if math.isnan(m):
            return False
        return m <= self.limit if self.relation == "<=" else m >= self.limit

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "measured": _finite_or_none(self.measured),
            "limit": self.limit,
            "relation": self.relation,
            "kind": self.kind,
            "passed": self.passed,
            "note": self.note,
        }


def status_from_checks(checks: Iterable[Check]) -> Status:
    """FAILED if a tolerance failed, else TARGET_MISSED if a target was missed, else PASSED.

    Unmeasured checks do not change the status; they make the result partial.
    """
    checks = list(checks)
    if any(c.kind == "tolerance" and c.passed is False for c in checks):
        return Status.FAILED
    if any(c.kind == "target" and c.passed is False for c in checks):
        return Status.TARGET_MISSED
    return Status.PASSED


@dataclass(frozen=True)
class StudyResult:
    """A study's outcome: status, headline, what it was held to, how to reproduce it, its data.

    - key, title: the study's identity (e.g. "equivalence", "Equivalence: MJED against the
      UFL oracle").
    - status: one of :class:`Status`.
    - headline: one line for a summary, with the figures that matter.
    - command: the exact command line that reproduces this result (with every option that
      ran).
    - checks: the tolerances and targets, each with its measured figure.
    - not_covered: what this run left out, in words ("quick sizes: cube-small instead of
      cube-paper"); non-empty makes the result partial.
    - reason: why it failed, was not run or raised (empty when passed).
    - protocol: how the numbers were produced when that matters for reading them (e.g. the
      timing protocol: calls per measurement, repeats, stopping rule).
    - data: the study's numbers, JSON-serialisable (written to results.json and --json).
    - blocks: the study's presentation (paragraphs, tables, figures) for the report.
    """

    key: str
    title: str
    status: Status
    headline: str
    command: str
    checks: Tuple[Check, ...] = ()
    not_covered: Tuple[str, ...] = ()
    reason: str = ""
    protocol: str = ""
    data: Mapping[str, Any] = field(default_factory=dict)
    blocks: Tuple[Block, ...] = ()
    seconds: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.status, Status):
            raise TypeError(
                f"StudyResult {self.key!r}: status must be a Status, not "
                f"{type(self.status).__name__}"
            )
        object.__setattr__(self, "checks", tuple(self.checks))
        object.__setattr__(self, "not_covered", tuple(self.not_covered))
        object.__setattr__(self, "blocks", tuple(self.blocks))
        if (
            self.status in (Status.NOT_RUN, Status.ERROR, Status.FAILED, Status.TARGET_MISSED)
            and not self.reason
        ):
            raise ValueError(
                f"StudyResult {self.key!r}: a {self.status.value} result must say why (reason)"
            )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_checks(
        cls,
        key: str,
        title: str,
        checks: Sequence[Check],
        *,
        headline: str,
        command: str,
        reason: str = "",
        **kwargs,
    ) -> "StudyResult":
        """The status follows the checks; the reason defaults to the failed or missed ones."""
        status = status_from_checks(checks)
        if status is not Status.PASSED and not reason:
            bad = [c for c in checks if c.passed is False]
            reason = f"{len(bad)} of {len(checks)} checks not met: " + "; ".join(
                _describe(c) for c in bad[:3]
            )
            if len(bad) > 3:
                reason += f"; and {len(bad) - 3} more"
        return cls(
            key=key,
            title=title,
            status=status,
            headline=headline,
            command=command,
            checks=tuple(checks),
            reason=reason,
            **kwargs,
        )

    @classmethod
    def not_run(cls, key: str, title: str, reason: str, command: str) -> "StudyResult":
        return cls(
            key=key,
            title=title,
            status=Status.NOT_RUN,
            headline=f"not run: {reason}",
            command=command,
            reason=reason,
        )

    @classmethod
    def error(
        cls, key: str, title: str, reason: str, command: str, blocks: Sequence[Block] = ()
    ) -> "StudyResult":
        return cls(
            key=key,
            title=title,
            status=Status.ERROR,
            headline=f"error: {reason}",
            command=command,
            reason=reason,
            blocks=tuple(blocks),
        )

    # ------------------------------------------------------------------ reading
    @property
    def unmeasured(self) -> Tuple[Check, ...]:
        return tuple(c for c in self.checks if c.passed is None)

    @property
    def partial(self) -> bool:
        """True when the run left something out or could not measure a check."""
        return bool(self.not_covered) or bool(self.unmeasured)

    @property
    def complete_pass(self) -> bool:
        """Passed, and nothing left out: the only case a summary may call 'passed' without
        qualification.
        """
        return self.status is Status.PASSED and not self.partial

    def with_seconds(self, seconds: float) -> "StudyResult":
        return replace(self, seconds=float(seconds))

    def to_dict(self) -> dict:
        return {
            "key": self.key,
            "title": self.title,
            "status": self.status.value,
            "partial": self.partial,
            "headline": self.headline,
            "command": self.command,
            "reason": self.reason,
            "not_covered": list(self.not_covered),
            "protocol": self.protocol,
            "checks": [c.to_dict() for c in self.checks],
            "seconds": self.seconds,
            "data": self.data,
        }


def worst_status(results: Iterable[StudyResult]) -> Status:
    statuses = [r.status for r in results]
    return max(statuses, key=_SEVERITY.__getitem__) if statuses else Status.NOT_RUN


def exit_code(results: Iterable[StudyResult], *, allow_incomplete: bool = False) -> int:
    """0 every study passed completely; 1 a check failed or a study raised; 3 a target missed,
    a study not run or a partial run (0 instead when ``allow_incomplete``).
    """
    results = list(results)
    if not results:
        return EXIT_INCOMPLETE
    worst = worst_status(results)
    if worst in (Status.FAILED, Status.ERROR):
        return EXIT_FAILED
    if all(r.complete_pass for r in results) or allow_incomplete:
        return EXIT_PASSED
    return EXIT_INCOMPLETE


def _describe(c: Check) -> str:
    return (
        f"{c.name}: {c.measured:.3g} (required {c.relation} {c.limit:g})"
        if c.measured is not None
        else c.name
    )


def _finite_or_none(x: Optional[float]) -> Optional[float]:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None
