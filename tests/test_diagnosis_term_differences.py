"""One scalar second derivative taken by finite differences inside the engine
(conformance.diagnosis.term_differences): the mistaken engines add to MJED's K, cell by cell,
the error of their own difference quotient of psi' (written here from the material's formula,
not from the module's derivatives); MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.second_derivative import curvature_basis, fit_invariant_curvature
from conformance.diagnosis.term_differences import (
    cell_invariants,
    energy_values,
    invariant_derivatives,
    pressure_difference_finding,
    term_difference_finding,
    volumetric_slip_finding,
)


def _state(material, seed=0):
    """(model, points, cells, x, K_o): MJED on a jittered box, deformed unevenly (many J)."""
    points, cells = box_mesh(3, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.12, 0.95, 0.97]).T + 0.04 * rng.standard_normal(points.shape)
    model = default_material(material)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    return model, points, cells, x, sp.csr_matrix(field.force_and_stiffness(x)[1])


def _engine_K(points, cells, x, K_o, invariant, lam):
    """The engine's K: the oracle's plus lam_c V_c g_c g_c^T (its error on psi'')."""
    basis = curvature_basis(points, cells, x, invariant)
    m = cells.shape[0]
    n = points.shape[0]
    return K_o + assemble(cells, n, np.zeros((m, 4, 3)), lam[:, None, None] * basis)[1]


def _restated(model, points, cells, x, K_o, K, invariant, code):
    inv = cell_invariants(cell_kinematics(points, cells, x)[2])
    derivs = invariant_derivatives(model, inv, invariant)
    _, lam = fit_invariant_curvature(points, cells, x, (K - K_o).tocsr(), K_o, invariant)
    figures = {"invariant": invariant} if code == "tangent-curvature" else {}
    term = Finding(code, "the term is wrong", FULL, "fitted", figures)
    return term_difference_finding(term, lam, derivs, inv[invariant])


def test_volumetric_f2_by_forward_differences_is_named_with_its_step():
    model, points, cells, x, K_o = _state("MooneyRivlin")
    J = cell_invariants(cell_kinematics(points, cells, x)[2])["J"]
    k0, h = model.k0, 1e-6
    dU = lambda J: k0 * np.log(J) / J  # noqa: E731 - U = k0/2 (ln J)^2
    d2U = k0 * (1.0 - np.log(J)) / J**2
    K = _engine_K(points, cells, x, K_o, "J", (dU(J + h) - dU(J)) / h - d2U)
    found = _restated(model, points, cells, x, K_o, K, "J", "volumetric")
    assert found is not None and found.code == "finite-difference-term", found
    assert found.figures["scheme"] == "forward"
    assert abs(found.figures["step"] / h - 1) < 0.1, found.figures
    assert "finite differences" in found.title and found.strength == FULL


def test_a_relative_step_is_told_from_an_absolute_one():
    """U'' by forward differences of U' with a step proportional to J (h J), as engines write a
    relative step, and with an absolute step: each named with its own kind of step.
    """
    model, points, cells, x, K_o = _state("MooneyRivlin", seed=4)
    J = cell_invariants(cell_kinematics(points, cells, x)[2])["J"]
    k0, h = model.k0, 1e-6
    dU = lambda J: k0 * np.log(J) / J  # noqa: E731 - U = k0/2 (ln J)^2
    d2U = k0 * (1.0 - np.log(J)) / J**2
    for proportional, step in ((True, h * J), (False, h)):
        K = _engine_K(points, cells, x, K_o, "J", (dU(J + step) - dU(J)) / step - d2U)
        found = _restated(model, points, cells, x, K_o, K, "J", "volumetric")
        assert found is not None and found.code == "finite-difference-term", found
        assert found.figures["proportional"] is proportional, found.title
        assert abs(found.figures["step"] / h - 1) < 0.1, found.figures
        assert ("relative step" in found.title) is proportional, found.title


def test_gent_log_curvature_by_central_differences_is_named():
    model, points, cells, x, K_o = _state("Gent", seed=1)
    I1b = cell_invariants(cell_kinematics(points, cells, x)[2])["I1b"]
    mu, Jm, h = model.mu, model.Jm, 0.05

    def dpsi(I):  # psi = -mu Jm / 2 ln(1 - (I1b - 3) / Jm)
        return 0.5 * mu / (1.0 - (I - 3.0) / Jm)

    d2psi = 0.5 * mu / Jm / (1.0 - (I1b - 3.0) / Jm) ** 2
    K = _engine_K(points, cells, x, K_o, "I1b", (dpsi(I1b + h) - dpsi(I1b - h)) / (2 * h) - d2psi)
    found = _restated(model, points, cells, x, K_o, K, "I1b", "tangent-curvature")
    assert found is not None and found.code == "finite-difference-term", found
    assert found.figures["scheme"] == "central"
    assert abs(found.figures["step"] / h - 1) < 0.1, found.figures


def test_a_term_wrong_or_slightly_scaled_is_not_called_differences():
    """The volumetric curvature halved (a real mistake: the finding stands), and scaled by
    1 + 3e-6 (small, but not the shape of a difference quotient: said slightly off, partly).
    """
    model, points, cells, x, K_o = _state("MooneyRivlin", seed=2)
    J = cell_invariants(cell_kinematics(points, cells, x)[2])["J"]
    d2U = model.k0 * (1.0 - np.log(J)) / J**2
    K = _engine_K(points, cells, x, K_o, "J", -0.5 * d2U)
    assert _restated(model, points, cells, x, K_o, K, "J", "volumetric") is None
    K = _engine_K(points, cells, x, K_o, "J", 3e-6 * d2U)
    found = _restated(model, points, cells, x, K_o, K, "J", "volumetric")
    assert found is not None and found.code == "volumetric", found
    assert found.strength == "partly explains" and "slightly off" in found.title


def test_an_ambiguous_case_is_settled_on_the_restated_term_partly():
    """A uniaxial case cannot tell I1b's curvature from I2b's; the kit's other case restates
    I1b's as differences: the ambiguous case gets that reading at "partly explains"; a restated
    term that is not among its options settles nothing.
    """
    from conformance.diagnosis.diagnose import Diagnosis
    from conformance.diagnosis.disambiguate import settle_ambiguity
    from conformance.diagnosis.findings import OBSERVED, ambiguous
    from conformance.judge.compare import Errors

    e = Errors(0.0, 1e-6, 0.0, 0.0)
    t1, t2, t3 = (f"the term d2W/d{n}2 is wrong" for n in ("I1b", "I2b", "J"))
    options = ambiguous([Finding("tangent-curvature", t, FULL, "fits") for t in (t1, t2)])
    assert options[0].strength == OBSERVED
    for restated, settles in ((t1, True), (t3, False)):
        fd = Finding(
            "finite-difference-term", "by finite differences", FULL, "h", {"restates": restated}
        )
        cases = [
            Diagnosis("uniaxial", "failed", e, options),
            Diagnosis("random", "failed", e, [fd]),
        ]
        out = settle_ambiguity(cases, [[0, 1]], ["uniaxial", "random"])
        first = out[0].findings[0]
        if settles:
            assert first.code == "finite-difference-term" and first.strength == "partly explains"
            assert "random" in first.evidence
        else:
            assert first.code == "ambiguous"


def _slip(model, points, cells, x, K_o, K):
    inv = cell_invariants(cell_kinematics(points, cells, x)[2])
    derivs = invariant_derivatives(model, inv, "J")
    _, lam = fit_invariant_curvature(points, cells, x, (K - K_o).tocsr(), K_o, "J")
    term = Finding("volumetric", "volumetric (J-only) tangent differs", FULL, "fitted", {})
    assert term_difference_finding(term, lam, derivs, inv["J"]) is None  # not a small error
    return volumetric_slip_finding(term, lam, derivs, inv["J"])


def test_volumetric_quotient_rule_sign_slip_is_named_as_such():
    """U''(J) = k0 (1 + ln J)/J^2 for k0 (1 - ln J)/J^2 (U = k0/2 (ln J)^2): 2 U'/J too much."""
    model, points, cells, x, K_o = _state("ArrudaBoyce")
    J = cell_invariants(cell_kinematics(points, cells, x)[2])["J"]
    K = _engine_K(points, cells, x, K_o, "J", 2.0 * model.k0 * np.log(J) / J**2)
    found = _slip(model, points, cells, x, K_o, K)
    assert found is not None and found.strength == FULL
    assert "U'' + 2 U'/J" in found.title and "quotient rule" in found.title, found.title
    # halved: a factor, said in simple numbers; an error of another form: nothing said
    found = _slip(
        model,
        points,
        cells,
        x,
        K_o,
        _engine_K(points, cells, x, K_o, "J", -0.5 * (model.k0 * (1.0 - np.log(J)) / J**2)),
    )
    assert found is not None and "1/2 U''" in found.title, found.title
    assert (
        _slip(
            model, points, cells, x, K_o, _engine_K(points, cells, x, K_o, "J", 0.3 * model.k0 * J)
        )
        is None
    )


def test_a_pressure_by_differences_of_u_is_named_through_its_rounding():
    """A mixed engine's p = (U(J + h) - U(J)) / h with h = 1e-8, in float64: truncation h/2 U''
    and the quotient's rounding (x + h rounded, U's values rounded) of the same order. Named with
    its step; the pressure scaled by 1 + 1e-6 (small, not a difference quotient) is not.
    """
    model, points, cells, x, _ = _state("MooneyRivlin", seed=5)
    inv = cell_invariants(cell_kinematics(points, cells, x)[2])
    J, k0, h = inv["J"], model.k0, 1e-8
    U = lambda J: 0.5 * k0 * np.log(J) ** 2  # noqa: E731
    dU = k0 * np.log(J) / J
    derivs = invariant_derivatives(model, inv, "J")
    values = energy_values(model, inv)
    found = pressure_difference_finding((U(J + h) - U(J)) / h - dU, values, derivs, J, "fitted")
    assert found is not None and found.code == "finite-difference-pressure", found
    assert found.figures["scheme"] == "forward" and abs(found.figures["step"] / h - 1) < 0.3
    assert pressure_difference_finding(1e-6 * dU, values, derivs, J, "fitted") is None
