"""A tangent with one invariant's curvature term wrong (conformance.diagnosis.second_derivative):
the mistaken stiffness is built here with the gradient of the invariant taken by complex step
(independent of the module's closed forms), one factor per cell, as an engine that linearises
a function of that invariant would.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.second_derivative import second_derivative_findings


def _i1b(F):
    return np.linalg.det(F) ** (-2.0 / 3.0) * np.einsum("mki,mki->m", F, F)


def _curvature_error(points, cells, x, invariant, lam):
    """sum_c lam_c V_c g_c g_c^T, g_c = dI/dx over the cell by complex step."""
    from mjed.mesh import shape_vectors

    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    G = np.empty_like(F)
    for k in range(3):
        for i in range(3):
            Fc = F.astype(complex)
            Fc[:, k, i] += 1e-30j
            G[:, k, i] = invariant(Fc).imag / 1e-30
    g = np.einsum("mki,mai->mak", G, D).reshape(-1, 12)
    Ke = (lam * np.abs(V0))[:, None, None] * g[:, :, None] * g[:, None, :]
    return assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]


def _oracle(points, cells, x):
    import mjed

    field = mjed.HyperelasticForceField(
        mjed.TetMesh(points, cells), default_material("VerondaWestmann")
    )
    return sp.csr_matrix(field.stiffness(x))


def test_a_linearised_function_of_i1b_is_named_in_a_random_state():
    points, cells = box_mesh(2, jitter=0.2, seed=5)
    rng = np.random.default_rng(5)
    x = points + 0.05 * rng.standard_normal(points.shape)
    K_o = _oracle(points, cells, x)
    lam = -rng.uniform(100.0, 300.0, len(cells))
    K = K_o + _curvature_error(points, cells, x, _i1b, lam)
    found = second_derivative_findings(points, cells, x, K, K_o, 1e-10)
    assert [f.figures["invariant"] for f in found] == ["I1b"], [f.title for f in found]
    assert "I1b" in found[0].title and found[0].strength == "explains"
    # a stiffness error that is not one invariant's curvature: nothing
    assert second_derivative_findings(points, cells, x, K_o * 1.001, K_o, 1e-10) == []


def test_the_j_curvature_is_named_only_as_one_function_of_j():
    """A function of J linearised in the tangent (its factor -psi''(J_c)) is named; the same
    term with a factor depending on more than J (an isochoric term along C^-1 (x) C^-1, the
    projection P~ of a decoupled tangent with a wrong sign: corpus 6) is not the J curvature,
    and on one J (a homogeneous stretch) the two cannot be told apart.
    """
    points, cells = box_mesh(2, jitter=0.2, seed=5)
    rng = np.random.default_rng(5)
    x = points + 0.05 * rng.standard_normal(points.shape)
    K_o = _oracle(points, cells, x)
    J = lambda F: np.linalg.det(F)  # noqa: E731
    from mjed.mesh import shape_vectors

    Jc = np.linalg.det(np.einsum("mai,maj->mij", x[cells], shape_vectors(points, cells)[1]))
    K = K_o + _curvature_error(points, cells, x, J, -3e4 / Jc**2)
    found = second_derivative_findings(points, cells, x, K, K_o, 1e-10)
    assert [f.figures.get("invariant") for f in found if f.code != "ambiguous"] == ["J"]
    K = K_o + _curvature_error(points, cells, x, J, -3e4 * rng.uniform(0.5, 1.5, len(cells)))
    assert not [f for f in second_derivative_findings(points, cells, x, K, K_o, 1e-10)
                if f.figures.get("invariant") == "J"]  # fmt: skip
    y = points @ np.diag([1.3, 1.0, 1.0]).T
    K_y = _oracle(points, cells, y)
    K = K_y + _curvature_error(points, cells, y, J, np.full(len(cells), -3e4))
    assert not [f for f in second_derivative_findings(points, cells, y, K, K_y, 1e-10)
                if f.figures.get("invariant") == "J"]  # fmt: skip


def test_parallel_gradients_are_ambiguous_not_named():
    """A homogeneous uniaxial stretch: the gradients of I1b and I2b are parallel."""
    points, cells = box_mesh(2)
    x = points @ np.diag([1.2, 1 / np.sqrt(1.2), 1 / np.sqrt(1.2)]).T
    K_o = _oracle(points, cells, x)
    K = K_o + _curvature_error(points, cells, x, _i1b, np.full(len(cells), -200.0))
    found = second_derivative_findings(points, cells, x, K, K_o, 1e-10)
    assert found[0].code == "ambiguous" and found[0].strength == "observed", found
    assert {f.figures.get("invariant") for f in found[1:]} >= {"I1b", "I2b"}


def test_an_elasticity_tensor_without_its_minor_symmetry_is_named():
    """A Neo-Hookean total-Lagrangian tangent with 2 s C^-1_IK C^-1_JL for the symmetrised
    s (C^-1_IK C^-1_JL + C^-1_IL C^-1_JK), contracted with F^T grad v unsymmetrised.
    """
    from mjed.mesh import shape_vectors

    points, cells = box_mesh(2, jitter=0.2, seed=6)
    x = points + 0.05 * np.random.default_rng(6).standard_normal(points.shape)
    K_o = _oracle(points, cells, x)
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    Ci = np.linalg.inv(F.swapaxes(1, 2) @ F)
    s = 300.0 - 50.0 * np.log(np.linalg.det(F))
    wrong = 2 * np.einsum("mIK,mJL->mIJKL", Ci, Ci)
    right = np.einsum("mIK,mJL->mIJKL", Ci, Ci) + np.einsum("mIL,mJK->mIJKL", Ci, Ci)
    BL = np.einsum("mkI,maJ->makIJ", F, D)
    Ke = np.einsum("makIJ,mIJKL,mblKL->makbl", BL, wrong - right, BL)
    Ke = ((np.abs(V0) * s)[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    K = K_o + assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]
    found = second_derivative_findings(points, cells, x, K, K_o, 1e-10)
    assert [f.code for f in found] == ["tangent-unsymmetrised"], [f.title for f in found]
    assert found[0].figures["tensor"] == "C^-1" and "symmetrised" in found[0].title
    # the coefficient of the unsymmetrised C^-1_IK C^-1_JL in the engine: 2 s
    assert abs(found[0].figures["coefficient_median"] / np.median(2 * s) - 1) < 0.2
