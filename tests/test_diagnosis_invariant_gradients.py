"""One invariant's gradient wrong in a hand-written first Piola stress, the stiffness right
(conformance.diagnosis.invariant_gradients): engines written here in F whose P has one piece
Psi_a dI_a/dF scaled, beside MJED's (right) stiffness; MJED stands in for the oracle.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble, cell_kinematics, piola_element_forces
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.invariant_gradients import gradient_findings, gradient_reading
from conformance.judge.compare import DOUBLE, errors, scales
from conformance.judge.oracle import Reference


def _case(material, stretch, noise):
    points, cells = box_mesh(3, jitter=0.2, seed=11)
    x = points @ np.diag(stretch).T
    x = x + noise * np.random.default_rng(11).standard_normal(points.shape)
    model = default_material(material)
    f_o, K_o = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model).force_and_stiffness(
        x
    )
    return points, cells, x, model, np.asarray(f_o), sp.csr_matrix(K_o)


def _with_piece(points, cells, x, f_o, piece, k):
    """The oracle's force with ``piece`` (m, 3, 3) of P scaled by k."""
    V0, D, _ = cell_kinematics(points, cells, x)
    extra = piola_element_forces(V0, D, (k - 1.0) * piece)
    return f_o + assemble(cells, points.shape[0], extra, None)[0]


def test_st_venant_kirchhoffs_ii_c_gradient_halved_is_named():
    """P = F (lam tr E I + 2 mu E) with mu tr(E^2) = mu/4 II_C - mu/2 I_C + const: the II_C
    piece is mu F C; written with half of it. St Venant-Kirchhoff's formula is in E, not in the
    invariants: Psi_a are read back from the oracle's stress.
    """
    points, cells, x, model, f_o, K_o = _case("StVenantKirchhoff", [1.1, 0.95, 0.9], 0.04)
    _, _, F = cell_kinematics(points, cells, x)
    f = _with_piece(points, cells, x, f_o, model.mu * F @ F.swapaxes(1, 2) @ F, 0.5)
    s = scales(0.5, 1.0, f_o, K_o)
    found = gradient_findings(model, points, cells, x, f, K_o, f_o, K_o, s, DOUBLE)
    assert [(x.figures["invariant"], x.figures["factor"]) for x in found] == [("II_C", 0.5)]
    assert "read back from the oracle's stress" in found[0].evidence


@pytest.mark.parametrize("k", [2.0, -1.0])
def test_a_piece_in_the_declared_invariants_is_named_with_its_factor(k):
    """Mooney-Rivlin's J piece (cof F) scaled: its slope from the declared energy."""
    from conformance.diagnosis.invariant_gradients import gradient_pieces, invariant_slopes

    points, cells, x, model, f_o, K_o = _case("MooneyRivlin", [1.1, 0.95, 0.9], 0.04)
    _, _, F = cell_kinematics(points, cells, x)
    slopes = invariant_slopes(model, F, "I1, I2, J")
    assert slopes is not None
    f = _with_piece(points, cells, x, f_o, gradient_pieces(F, slopes, "I1, I2, J")[2], k)
    s = scales(0.5, 1.0, f_o, K_o)
    found = gradient_findings(model, points, cells, x, f, K_o, f_o, K_o, s, DOUBLE)
    assert [(x.figures["invariant"], x.figures["factor"]) for x in found] == [("J", k)], found


def test_other_force_errors_or_a_wrong_stiffness_are_not_a_piece():
    points, cells, x, model, f_o, K_o = _case("MooneyRivlin", [1.1, 0.95, 0.9], 0.04)
    s = scales(0.5, 1.0, f_o, K_o)
    rng = np.random.default_rng(0)
    noisy = f_o * (1 + 1e-3 * rng.standard_normal(f_o.shape))
    assert gradient_findings(model, points, cells, x, noisy, K_o, f_o, K_o, s, DOUBLE) == []
    _, _, F = cell_kinematics(points, cells, x)
    f = _with_piece(points, cells, x, f_o, 2.0 * F, 3.0)
    assert gradient_findings(model, points, cells, x, f, 1.01 * K_o, f_o, K_o, s, DOUBLE) == []


def test_on_alike_cells_the_case_fits_a_piece_without_telling_which():
    points, cells, x, model, f_o, K_o = _case("StVenantKirchhoff", [1.2, 0.93, 0.93], 0.0)
    _, _, F = cell_kinematics(points, cells, x)
    f = _with_piece(points, cells, x, f_o, model.mu * F @ F.swapaxes(1, 2) @ F, 0.5)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K_o, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("u", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ci = SimpleNamespace(points=points, cells=cells, positions=x, model=model)
    out = SimpleNamespace(force=f, stiffness=K_o)
    d = gradient_reading(diag, ci, out, Reference(0.0, f_o, K_o), s)
    assert not d.causes
    assert "invariant-gradient-piece" in d.findings[0].figures["fits_codes"]


def test_a_slope_wrong_in_p_and_in_its_hessian_term_is_named():
    """Mooney-Rivlin in (I_C, II_C, J) with dI2b/dII_C typed +J^(-4/3)/2: Psi_IIC = c2
    dI2b/dII_C flips in P and in Psi_IIC d2II_C/dF2, written here by hand; the second
    derivatives of W (zero for c2's linear term) right.
    """
    from conformance.diagnosis.elements import tangent_element_matrices

    points, cells, x, model, f_o, K_o = _case("MooneyRivlin", [1.1, 0.95, 0.9], 0.04)
    V0, D, F = cell_kinematics(points, cells, x)
    J = np.linalg.det(F)
    psi = -0.5 * model.c2 * J ** (-4.0 / 3.0)  # dW/dII_C of c2 (I2b - 3)
    C = F.swapaxes(1, 2) @ F
    B = F @ F.swapaxes(1, 2)
    eye = np.eye(3)
    H = 4.0 * (
        np.einsum("kl,mLI->mkIlL", eye, C)
        + np.einsum("mkL,mlI->mkIlL", F, F)
        + np.einsum("mkl,IL->mkIlL", B, eye)
    )
    k = -1.0
    m, n = cells.shape[0], points.shape[0]
    fe = piola_element_forces(V0, D, (k - 1.0) * psi[:, None, None] * 4.0 * F @ C)
    Ke = tangent_element_matrices(V0, D, (k - 1.0) * psi[:, None, None, None, None] * H)
    f = f_o + assemble(cells, n, fe, None)[0]
    K = K_o + assemble(cells, n, np.zeros((m, 4, 3)), Ke)[1]
    s = scales(0.5, 1.0, f_o, K_o)
    found = gradient_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE)
    assert [(x.code, x.figures["invariant"], x.figures["factor"]) for x in found] == [
        ("invariant-slope-piece", "II_C", -1.0)
    ], [x.title for x in found]
    # the force alone so (its tangent term right too): the gradient reading, not this one
    found = gradient_findings(model, points, cells, x, f, K_o, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == ["invariant-gradient-piece"]
