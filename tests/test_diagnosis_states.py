"""Force or stiffness evaluated at another state (conformance.diagnosis.states): a tangent kept
from the rest state, or a stiffness (or force) left from another case of the kit, is named with
that state; a zero force is not taken for the rest state's.
"""

from __future__ import annotations

import numpy as np
import pytest

from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx"),
]


def _oracle(case):
    from reference_fem import UFLOracle

    return UFLOracle(case.points, case.cells, case.model)


def test_a_tangent_kept_from_the_rest_state_is_named():
    from conformance.protocol import check_implementation

    def engine(case):  # a modified Newton's: K assembled once, at x = X
        o = _oracle(case)
        return o.force_and_stiffness(case.positions)[0], o.force_and_stiffness(case.points)[1]

    run = check_implementation(engine, material="Gent", states=("random",), probes=False)
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
    assert named[0].code == "stiffness-other-state", outcome.diagnosis.text()
    assert named[0].figures["rest"] and "rest state" in named[0].title


@pytest.mark.parametrize("which", ["stiffness", "both"])
def test_an_output_left_from_another_case_of_the_kit_is_named(which):
    from conformance.protocol import check_implementation

    first: list = []

    def engine(case):  # keeps the first case's positions (a stale state between calls)
        if not first:
            first.append(np.array(case.positions))
        o = _oracle(case)
        f, K = o.force_and_stiffness(first[0])
        return (o.force_and_stiffness(case.positions)[0] if which == "stiffness" else f), K

    run = check_implementation(
        engine, material="MooneyRivlin", states=("uniaxial", "random"), probes=False
    )
    passed, failed = run.outcomes
    assert passed.status == "passed", passed.diagnosis.text()
    named = failed.diagnosis.causes
    assert failed.status == "failed" and len(named) == 1, failed.diagnosis.text()
    code = "stiffness-other-state" if which == "stiffness" else "other-state"
    assert named[0].code == code, failed.diagnosis.text()
    assert "'uniaxial'" in named[0].title and not named[0].figures["rest"]


def test_a_zero_force_is_not_the_rest_state():
    from conformance.protocol import check_implementation

    def engine(case):
        f, K = _oracle(case).force_and_stiffness(case.positions)
        return 0.0 * f, K

    run = check_implementation(engine, material="NeoHookean", states=("random",), probes=False)
    (outcome,) = run.outcomes
    assert outcome.status == "failed"
    assert not any("state" in f.code for f in outcome.diagnosis.findings), outcome.diagnosis.text()


def test_verdict_only_keeps_the_verdicts_and_says_the_cause_was_not_looked_for():
    # The same mistaken engine judged without the readings of mistakes: the verdicts are
    # those of the full check, and the failed case does not claim "unexplained".
    from conformance.protocol import check_implementation

    def engine(case):  # the tangent kept from the rest state, as above
        o = _oracle(case)
        return o.force_and_stiffness(case.positions)[0], o.force_and_stiffness(case.points)[1]

    def check(read_causes):
        return check_implementation(
            engine,
            material="Gent",
            states=("rest", "random"),
            probes=False,
            read_causes=read_causes,
        ).outcomes

    full, quick = check(True), check(False)
    assert [o.status for o in quick] == [o.status for o in full] == ["passed", "failed"]
    assert full[1].diagnosis.causes[0].code == "stiffness-other-state"
    first = quick[1].diagnosis.findings[0]
    assert first.code == "causes-not-read" and not quick[1].diagnosis.causes, first
    assert "verdict-only" in first.title
