"""A cause named on one case is held against the kit's other cases of the same engine
(conformance.diagnosis.corroborate).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.findings import FULL, OBSERVED, Finding, ambiguous
from conformance.judge.compare import DOUBLE, Errors

WRONG = Errors(force=1e-16, stiffness=0.2, energy=0.0, symmetry=0.0)
RIGHT = Errors(force=1e-16, stiffness=1e-15, energy=0.0, symmetry=0.0)


def _diag(case, findings, errors=WRONG, verdict="failed"):
    return Diagnosis(case, verdict, errors, findings, tolerances=DOUBLE)


def _cause(title="P^T used as P"):
    return Finding("stress-measure-piola-transposed", title, FULL, "force 1e-16, stiffness 6e-16")


def _nothing():
    return Finding("unexplained", "unexplained", OBSERVED, "no tested hypothesis fits")


def test_a_cause_that_leaves_another_case_unexplained_is_not_named():
    from conformance.diagnosis.corroborate import corroborate

    named = _diag("uniaxial", [_cause()])
    other = _diag("random", [_nothing()])
    out = corroborate([named, other], [[0, 1]], ["uniaxial", "random"])
    d = out[0]
    assert not d.causes, d.findings
    lead = d.findings[0]
    assert lead.code == "uncorroborated" and lead.strength == OBSERVED
    assert "P^T used as P" in lead.title and "random" in lead.title
    assert lead.figures["unexplained_cases"] == ["random"]
    assert d.findings[1].title == "(this case only) P^T used as P"
    assert d.findings[1].strength == OBSERVED
    assert out[1] is other


def test_what_does_not_contradict_a_cause():
    from conformance.diagnosis.corroborate import corroborate

    named = _diag("uniaxial", [_cause()])
    # explained by the same cause, passed, or failing only through the energy or the probes
    same = _diag("random", [_cause()])
    passed = _diag("random", [], errors=RIGHT, verdict="passed")
    energy_only = _diag("random", [_nothing()], errors=Errors(1e-16, 1e-15, 0.3, 0.0))
    not_read = _diag("random", [Finding("causes-not-read", "not looked for", OBSERVED, "")])
    for other in (same, passed, energy_only, not_read):
        assert corroborate([named, other], [[0, 1]], ["u", "r"])[0] is named
    # another model or mesh is another group
    lost = _diag("random", [_nothing()])
    assert corroborate([named, lost], [[0], [1]], ["u", "r"])[0] is named


def test_a_case_that_fits_a_cause_but_cannot_tell_it_apart_does_not_contradict_it():
    """A homogeneous state's single J fits the volumetric tangent U''(J) exactly but cannot tell
    it from another term along C^-1 (x) C^-1: named where J varies, that cause stands. A case
    whose exact-but-ambiguous fits are other causes still contradicts it.
    """
    from conformance.diagnosis.corroborate import corroborate, extend_consistent, fits_codes

    vol = Finding("volumetric", "volumetric (J-only) tangent differs", FULL, "stiffness 5e-15")
    named = _diag("random", [vol])

    def single_j(codes):
        figs = {"fits_codes": codes}
        lead = Finding("unexplained", "unexplained", OBSERVED, "closest: ...", figs)
        return _diag("uniaxial", [lead])

    consistent = single_j(["volumetric"])
    assert fits_codes(consistent) == {"volumetric"}
    assert corroborate([named, consistent], [[0, 1]], ["r", "u"])[0] is named
    # and the ambiguous case is given the cause, with the case that told it apart
    out = extend_consistent([named, consistent], [[0, 1]], ["r", "u"])
    assert out[0] is named
    head = out[1].findings[0]
    assert head.code == "volumetric" and head.strength == FULL and head.title == vol.title
    assert head.figures["named_on"] == "r" and "closest: ..." in head.evidence
    # not from a cause that is not one of the fits, nor from an observation
    for other in (_cause(), replace(vol, strength=OBSERVED)):
        assert (
            extend_consistent([_diag("r", [other]), consistent], [[0, 1]], ["r", "u"])[1]
            is consistent
        )
    for codes in ([], ["tangent-curvature"]):
        out = corroborate([named, single_j(codes)], [[0, 1]], ["r", "u"])[0]
        assert not out.causes and out.findings[0].code == "uncorroborated"


def test_a_fit_listed_with_its_invariant_takes_only_that_invariants_cause():
    """The fit "stress-derivative-rewritten:J" (a single J fits any slip in dW/dJ) takes a
    hand-written dW/dJ named where J varies, not a hand-written dW/dI1.
    """
    from conformance.diagnosis.corroborate import corroborate, extend_consistent

    lead = Finding(
        "unexplained",
        "unexplained",
        OBSERVED,
        "",
        {"fits_codes": ["stress-derivative-rewritten:J"]},
    )
    one_j = _diag("uniaxial", [lead])
    for invariant, given in (("J", True), ("I1", False)):
        cause = Finding("stress-derivative-rewritten", "dW/dJ", FULL, "", {"invariant": invariant})
        named = _diag("random", [cause])
        out = extend_consistent(
            corroborate([named, one_j], [[0, 1]], ["r", "u"]), [[0, 1]], ["r", "u"]
        )
        assert bool(out[0].causes) is given
        assert (out[1].findings[0].code == "stress-derivative-rewritten") is given


def test_ambiguous_causes_are_held_the_same_way():
    from conformance.diagnosis.corroborate import corroborate

    both = _diag("uniaxial", ambiguous([_cause("I1b term"), _cause("I2b term")]))
    out = corroborate([both, _diag("random", [_nothing()])], [[0, 1]], ["u", "r"])[0]
    assert not out.causes
    assert "I1b term | I2b term" in out.findings[0].title


@pytest.mark.oracle
def test_a_check_does_not_name_what_one_state_alone_shows():
    """An engine whose stiffness is doubled on the uniaxial state and noisy on the random one:
    "stiffness 2 times" fits the first case alone and is not named; doubled on both states it
    is named on both.
    """
    pytest.importorskip("dolfinx")
    import scipy.sparse as sp

    import mjed
    from conformance.protocol import check_implementation
    from mjed.materials import NeoHookean

    def engine(noisy: bool):
        def run(case):
            field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
            f, K = field.force_and_stiffness(case.positions)
            K = sp.csr_matrix(K)
            if noisy and case.case_id.endswith("random"):
                C = K.tocoo()
                rng = np.random.default_rng(1)
                N = sp.csr_matrix(
                    (rng.standard_normal(C.nnz) * 1e-3 * abs(C.data).max(), (C.row, C.col)),
                    shape=K.shape,
                )
                return f, K + N + N.T
            return f, 2.0 * K

        return run

    material = NeoHookean(mu=1000.0, lam=5000.0)
    kw = dict(material=material, mesh="cube-small", states=("uniaxial", "random"), probes=False)
    mixed = check_implementation(engine(noisy=True), **kw)
    uni, rnd = mixed.outcomes
    assert uni.status == rnd.status == "failed"
    assert rnd.diagnosis.findings[0].code == "unexplained", rnd.diagnosis.text()
    assert not uni.diagnosis.causes, uni.diagnosis.text()
    assert uni.diagnosis.findings[0].code == "uncorroborated", uni.diagnosis.text()
    doubled = check_implementation(engine(noisy=False), **kw)
    for o in doubled.outcomes:
        assert o.diagnosis.causes, o.diagnosis.text()


def test_a_full_cause_against_another_case_explained_partly_by_another_is_not_named():
    """Corpus 13's Ogden engine: a fitted volumetric stress coefficient explains the uniaxial
    case fully, while the general case is explained only partly by another reading (its force
    alone): the fit is not named. The same cause partly named in the other case contradicts
    nothing.
    """
    from conformance.diagnosis.corroborate import corroborate
    from conformance.diagnosis.findings import PARTIAL

    full = _diag("uniaxial", [Finding("stress-coefficient", "volumetric x 1.456", FULL, "fit")])
    partly = _diag("random", [Finding("mjed-part", "your force: J part", PARTIAL, "force only")])
    out = corroborate([full, partly], [[0, 1]], ["uniaxial", "random"])
    assert not out[0].causes and out[0].findings[0].code == "uncorroborated", out[0].findings
    assert out[1] is partly  # a partial reading is not demoted by a full one elsewhere
    same = _diag("random", [Finding("stress-coefficient", "volumetric x 1.2", PARTIAL, "fit")])
    out = corroborate([full, same], [[0, 1]], ["uniaxial", "random"])
    assert out[0] is full and out[1] is same


def test_a_j_only_energy_named_on_a_single_j_takes_the_cause_another_case_tells_apart():
    """A homogeneous state's single J fits a J-only energy change exactly, and as well every
    gradient scaled (F = k F leaves I1b and I2b unchanged): named on the case where J varies,
    the gradients' scale is given to the single-J case too; a cause it does not list is not.
    """
    from conformance.diagnosis.corroborate import extend_consistent, fits_codes

    figs = {"fits_codes": ["volumetric", "gradients-scaled"]}
    one_j = _diag("uniaxial", [Finding("volumetric", "J-only energy differs", FULL, "", figs)])
    assert fits_codes(one_j) == {"volumetric", "gradients-scaled"}
    scaled = Finding("gradients-scaled", "shape-function gradients twice", FULL, "exact")
    out = extend_consistent([_diag("random", [scaled]), one_j], [[0, 1]], ["r", "u"])
    assert out[1].findings[0].code == "gradients-scaled"
    assert out[1].findings[0].figures["named_on"] == "r"
    out = extend_consistent([_diag("random", [_cause()]), one_j], [[0, 1]], ["r", "u"])
    assert out[1] is one_j


def _rounded_part(parameter="a"):
    return Finding(
        "single-precision-part-scalar",
        f"a scalar of the energy's part in {parameter} computed in single precision (float32)",
        FULL,
        "lambda per cell, drawn at random",
        {"parameter": parameter, "covers": ["parameter-value"], "covers_relative": 1e-5},
    )


def _parameter(name="a", value=3000.00029, declared=3000.0):
    return Finding(
        "parameter-value",
        f"parameter {name} = {value} in your engine where the case has {declared}",
        FULL,
        "the oracle with it: force error 6e-17",
        {"parameter": name, "value": value, "declared": declared},
    )


def test_a_parameter_off_by_float32s_size_is_covered_by_a_rounding_per_cell():
    from conformance.diagnosis.corroborate import extend_covered

    rounded = _diag("random", [_rounded_part()])
    ids = ["uniaxial", "random"]
    out = extend_covered([_diag("uniaxial", [_parameter()]), rounded], [[0, 1]], ids)
    d = out[0]
    assert [f.code for f in d.causes] == ["single-precision-part-scalar"]
    assert d.findings[0].figures["named_on"] == "random"
    assert "3000.00029" in d.findings[0].evidence  # the case's own fit kept in the evidence
    assert d.findings[1].strength == OBSERVED and d.findings[1].code == "parameter-value"
    assert out[1] is rounded
    # not covered: a real parameter mistake, another parameter, another group
    for other in (_parameter(value=3300.0), _parameter("k0", 8e4 * (1 + 1e-7), 8e4)):
        case = _diag("uniaxial", [other])
        assert extend_covered([case, rounded], [[0, 1]], ids)[0] is case
    case = _diag("uniaxial", [_parameter()])
    assert extend_covered([case, rounded], [[0], [1]], ids)[0] is case
