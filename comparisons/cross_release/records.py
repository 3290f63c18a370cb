"""What the cross-release check measures, as typed records.

:func:`comparisons.cross_release.study.compare_snapshots` gives a :class:`SnapshotDiff`;
:func:`comparisons.cross_release.study.cross_release_check` gives a :class:`CrossReleaseResult`: the
stacks that ran (:class:`StackRun`), each compared with the first (:class:`StackComparison`),
and those not installed (:class:`MissingStack`) or that failed (:class:`StackError`). The
study's checks, tables and text read them by attribute; ``to_dict()`` is the JSON written by
``--json`` (the keys as before these records existed), and ``from_dict()`` reads it back (as
:func:`comparisons.cross_release.study.provenance_summary` does), naming the file and the key of
anything missing or mistyped. Differences are relative (dimensionless), times in seconds.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

from common.json_fields import JSONFields
from common.record_fields import RecordFields

__all__ = [
    "QUANTITIES",
    "SnapshotDiff",
    "StackRun",
    "StackComparison",
    "MissingStack",
    "StackError",
    "CrossReleaseResult",
]

#: The compared quantities, in the order of the fields ``<quantity>_rel_diff``.
QUANTITIES = ("energy", "force", "stiffness")


@dataclass(frozen=True)
class SnapshotDiff:
    """The worst relative differences of one snapshot from the reference, over its cases.

    n_cases: the cases compared; energy_rel_diff: max |E_a - E_b| / |E_a|; force_rel_diff:
    max ||f_a - f_b||_2 / ||f_a||_2; stiffness_rel_diff: max ||K_a - K_b||_F / ||K_a||_F (the
    absolute difference where the reference is zero); passed: all three within the tolerance.
    """

    n_cases: int
    energy_rel_diff: float
    force_rel_diff: float
    stiffness_rel_diff: float
    passed: bool

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.count("n_cases")
        f.flag("passed")

    def by_quantity(self) -> Tuple[Tuple[str, float], ...]:
        """(quantity, relative difference) for energy, force and stiffness."""
        return tuple((q, getattr(self, f"{q}_rel_diff")) for q in QUANTITIES)

    @property
    def worst(self) -> float:
        """The largest of the three relative differences."""
        return max(self.energy_rel_diff, self.force_rel_diff, self.stiffness_rel_diff)

    def to_dict(self) -> Dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_fields(cls, f: JSONFields) -> "SnapshotDiff":
        return f.build(
            cls,
            n_cases=f.integer("n_cases"),
            **{f"{q}_rel_diff": f.number(f"{q}_rel_diff") for q in QUANTITIES},
            passed=f.flag("passed"),
        )


@dataclass(frozen=True)
class StackRun:
    """One stack's snapshot: its label, interpreter and rank count, the versions it reported
    (python, dolfinx, ufl, petsc, numpy, mpi, and ffcx, basix where installed), the cells of the
    snapshot mesh on each rank, and the seconds the snapshot took (to 0.1 s).
    """

    label: str
    python: str
    ranks: int
    versions: Mapping[str, Any]
    cells_per_rank: Tuple[int, ...]
    seconds: float

    def __post_init__(self) -> None:
        f = RecordFields(self, name=f"StackRun {self.label!r}")
        f.count("ranks", minimum=1)
        f.mapping("versions")
        f.counts("cells_per_rank")

    def to_dict(self) -> Dict[str, Any]:
        return {
            "label": self.label,
            "python": self.python,
            "ranks": self.ranks,
            "versions": dict(self.versions),
            "cells_per_rank": list(self.cells_per_rank),
            "seconds": self.seconds,
        }

    @classmethod
    def from_fields(cls, f: JSONFields) -> "StackRun":
        return f.build(
            cls,
            label=f.text("label"),
            python=f.text("python"),
            ranks=f.integer("ranks"),
            versions=f.mapping("versions"),
            cells_per_rank=tuple(f.integers("cells_per_rank")),
            seconds=f.number("seconds"),
        )


@dataclass(frozen=True)
class StackComparison:
    """A stack's snapshot against the reference stack's (``label`` names the stack)."""

    label: str
    diff: SnapshotDiff

    def to_dict(self) -> Dict[str, Any]:
        """The label, then the differences, in one flat object."""
        return {"label": self.label, **self.diff.to_dict()}

    @classmethod
    def from_fields(cls, f: JSONFields) -> "StackComparison":
        return f.build(cls, label=f.text("label"), diff=SnapshotDiff.from_fields(f))


@dataclass(frozen=True)
class MissingStack:
    """A stack not installed here (no interpreter, or one that cannot import dolfinx)."""

    label: str
    reason: str

    @classmethod
    def from_fields(cls, f: JSONFields) -> "MissingStack":
        return f.build(cls, label=f.text("label"), reason=f.text("reason"))


@dataclass(frozen=True)
class StackError:
    """A stack that is installed but whose snapshot failed (``error``: why, with its output)."""

    label: str
    error: str

    @classmethod
    def from_fields(cls, f: JSONFields) -> "StackError":
        return f.build(cls, label=f.text("label"), error=f.text("error"))


@dataclass(frozen=True)
class CrossReleaseResult:
    """The check: every stack's snapshot compared with the first that ran.

    tolerance: the largest relative difference allowed; reference: the label of the first
    stack that ran (None when none did); stacks: those that ran, in order; comparisons: one per
    stack after the first, in the same order; missing: the stacks not installed here; errors:
    the stacks that exist but failed to run; figures: none so far (kept for the JSON's shape).
    """

    tolerance: float
    reference: Optional[str]
    stacks: Tuple[StackRun, ...]
    comparisons: Tuple[StackComparison, ...]
    missing: Tuple[MissingStack, ...] = ()
    errors: Tuple[StackError, ...] = ()
    figures: Tuple[str, ...] = ()

    def __post_init__(self) -> None:
        f = RecordFields(self)
        for name, kind in (
            ("stacks", StackRun),
            ("comparisons", StackComparison),
            ("missing", MissingStack),
            ("errors", StackError),
        ):
            f.records(name, kind)
        f.texts("figures")
        f.real("tolerance", positive=True)
        first = self.stacks[0].label if self.stacks else None
        if self.reference != first:
            raise ValueError(
                f"CrossReleaseResult: reference {self.reference!r} is not the first stack that "
                f"ran ({first!r})"
            )
        compared, others = [c.label for c in self.comparisons], [s.label for s in self.stacks[1:]]
        if compared != others:
            raise ValueError(
                f"CrossReleaseResult: comparisons {compared} do not match the stacks after the "
                f"reference {others}"
            )

    @property
    def passed(self) -> bool:
        """True when at least two stacks ran, none failed and every comparison passed."""
        return bool(
            len(self.stacks) >= 2
            and not self.errors
            and all(c.diff.passed for c in self.comparisons)
        )

    @property
    def not_run(self) -> Tuple[str, ...]:
        """The labels of the stacks missing here, then of those that failed."""
        return tuple(m.label for m in self.missing) + tuple(e.label for e in self.errors)

    def to_dict(self) -> Dict[str, Any]:
        """The JSON form (the keys and their order as the check has always written them)."""
        return {
            "tolerance": self.tolerance,
            "reference": self.reference,
            "stacks": [s.to_dict() for s in self.stacks],
            "comparisons": [c.to_dict() for c in self.comparisons],
            "missing": [asdict(m) for m in self.missing],
            "errors": [asdict(e) for e in self.errors],
            "figures": list(self.figures),
            "passed": self.passed,
        }

    @classmethod
    def from_dict(cls, payload: Any, source: str = "<dict>") -> "CrossReleaseResult":
        """Inverse of :meth:`to_dict`, validated.

        Raises:
            RecordError: a key missing or mistyped, records that do not fit together, or a
                ``passed`` that its comparisons contradict (each named, with ``source``).
        """
        f = JSONFields(payload, source)
        result = f.build(
            cls,
            tolerance=f.number("tolerance"),
            reference=f.optional_text("reference"),
            stacks=tuple(StackRun.from_fields(s) for s in f.objects("stacks")),
            comparisons=tuple(StackComparison.from_fields(c) for c in f.objects("comparisons")),
            missing=tuple(MissingStack.from_fields(m) for m in f.objects("missing")),
            errors=tuple(StackError.from_fields(e) for e in f.objects("errors")),
            figures=tuple(f.texts("figures")),
        )
        if f.flag("passed") != result.passed:
            raise f.error("passed", f"{f.flag('passed')} contradicts the comparisons and errors")
        return result
