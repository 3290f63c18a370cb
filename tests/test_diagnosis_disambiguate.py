"""Ambiguity settled by another case of the kit (conformance.diagnosis.disambiguate)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from conformance.diagnosis.findings import FULL, OBSERVED, Finding, ambiguous


@dataclass(frozen=True)
class _Diag:
    findings: Sequence[Finding]


def _cause(title):
    return Finding("tangent-curvature", title, FULL, "fits", {})


def _observed():
    return Finding("inconsistent-stiffness", "not the derivative", OBSERVED, "probes", {})


def test_the_cause_another_case_names_alone_settles_the_ambiguity():
    from conformance.diagnosis.disambiguate import settle_ambiguity

    both = _Diag([*ambiguous([_cause("I1b term"), _cause("I2b term")]), _observed()])
    alone = _Diag([_cause("I1b term"), _observed()])
    out = settle_ambiguity([both, alone], [[0, 1]], ["uniaxial", "random"])
    first = out[0].findings[0]
    assert first.title == "I1b term" and first.strength == FULL, out[0].findings
    assert "random" in first.evidence and "I2b term" in first.evidence
    assert [f.code for f in out[0].findings[1:]] == ["inconsistent-stiffness"]
    assert out[1] is alone


def test_nothing_is_settled_without_a_single_cause_in_the_group():
    from conformance.diagnosis.disambiguate import settle_ambiguity

    both = _Diag(ambiguous([_cause("I1b term"), _cause("I2b term")]))
    other = _Diag([_cause("J term")])  # explains the other case, not this one
    assert settle_ambiguity([both, other], [[0, 1]], ["a", "b"])[0] is both
    elsewhere = _Diag([_cause("I1b term")])  # another model or mesh: another group
    assert settle_ambiguity([both, elsewhere], [[0], [1]], ["a", "b"])[0] is both
    twice = _Diag(ambiguous([_cause("I1b term"), _cause("I2b term")]))
    assert settle_ambiguity([both, twice], [[0, 1]], ["a", "b"])[0] is both
