"""A tangent whose second derivative in one invariant is wrong: the force is right, and the
stiffness error is, cell by cell, a multiple of g g^T with g the gradient of one invariant.

For W = psi(I) + (the rest), the Hessian holds psi''(I) dI (x) dI. An engine that linearises a
function of an invariant in its tangent (the exponential of Veronda-Westmann's or Costa's
``exp(u)`` taken as constant, a Gent log without its curvature) leaves that rank-one term out
or gets it wrong, with a factor that differs per cell. The fit: D = K - K_o against
sum_c lambda_c V_c g_c g_c^T, g_c the gradient of I over the cell's 12 dofs, one unknown per
cell (linear least squares), for I among I1, I2, I1b, I2b and J. Named when the residual is
within the stiffness tolerance (for J, only when the factor is one function of J over cells of
distinct J: any term along C^-1 (x) C^-1 fits dJ (x) dJ with a free factor); two invariants
that fit (their gradients parallel in this state, e.g. a homogeneous uniaxial stretch) are both
shown, as ambiguous.

The same per-cell fit tests an elasticity tensor that holds A (.) A (A_IK A_JL; A = C^-1, as in
every tangent with ln J or J^p terms written in the total-Lagrangian form, or I) without its
minor symmetrisation and is contracted with the unsymmetrised F^T grad v: the error is then,
per cell, a multiple of BL : (A_IK A_JL - A_IL A_JK) / 2 : BL.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.j_functions import j_function_line, j_function_steps

__all__ = [
    "INVARIANTS",
    "fit_invariant_curvature",
    "second_derivative_findings",
    "second_derivative_reading",
    "fit_cell_term",
    "curvature_basis",
    "curvature_of",
    "unsymmetrised_basis",
]


def _inv_t(F):
    return np.linalg.inv(F).swapaxes(1, 2)


def _grad_i1(F):
    return 2.0 * F


def _grad_i2(F):
    C = F.swapaxes(1, 2) @ F
    I1 = np.trace(C, axis1=1, axis2=2)
    return 2.0 * (I1[:, None, None] * F - F @ C)


def _grad_j(F):
    return np.linalg.det(F)[:, None, None] * _inv_t(F)


def _grad_i1b(F):
    J = np.linalg.det(F)
    I1 = np.einsum("mki,mki->m", F, F)
    return J[:, None, None] ** (-2.0 / 3.0) * (
        2.0 * F - (2.0 / 3.0) * I1[:, None, None] * _inv_t(F)
    )


def _grad_i2b(F):
    J = np.linalg.det(F)
    C = F.swapaxes(1, 2) @ F
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    return J[:, None, None] ** (-4.0 / 3.0) * (
        _grad_i2(F) - (4.0 / 3.0) * I2[:, None, None] * _inv_t(F)
    )


#: invariant -> dI/dF (m, 3, 3) from F (m, 3, 3).
INVARIANTS: Dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "I1b": _grad_i1b,
    "I2b": _grad_i2b,
    "I1": _grad_i1,
    "I2": _grad_i2,
    "J": _grad_j,
}


def curvature_basis(points, cells, x, invariant: str) -> np.ndarray:
    """(m, 12, 12): V_c g_c g_c^T, g_c the gradient of ``invariant`` over the cell's dofs."""
    return curvature_of(*cell_kinematics(points, cells, x), invariant)


def curvature_of(V0: np.ndarray, Dg: np.ndarray, F: np.ndarray, invariant: str) -> np.ndarray:
    """:func:`curvature_basis` from the cells' rest volumes V0 (m,), shape gradients Dg
    (m, 4, 3) and deformation gradients F (m, 3, 3).
    """
    g = np.einsum("mki,mai->mak", INVARIANTS[invariant](F), Dg).reshape(-1, 12)
    return V0[:, None, None] * g[:, :, None] * g[:, None, :]


def unsymmetrised_basis(points, cells, x, tensor: str) -> np.ndarray:
    """(m, 12, 12): V_c BL : X : BL with BL_akIJ = F_kI D_aJ (the variation of E written
    without its symmetrisation) and X_IJKL = (A_IK A_JL - A_IL A_JK) / 2, A = C^-1 or I: what
    an elasticity tensor holding A (.) A without its minor symmetrisation adds (per unit of
    its coefficient) to the material tangent.
    """
    V0, Dg, F = cell_kinematics(points, cells, x)
    if tensor == "C^-1":
        A = np.linalg.inv(F.swapaxes(1, 2) @ F)
    else:
        A = np.broadcast_to(np.eye(3), F.shape)
    X = 0.5 * (np.einsum("mIK,mJL->mIJKL", A, A) - np.einsum("mIL,mJK->mIJKL", A, A))
    BL = np.einsum("mkI,maJ->makIJ", F, Dg)
    out = np.einsum("makIJ,mIJKL,mblKL->makbl", BL, X, BL)
    return (V0[:, None, None, None, None] * out).reshape(-1, 12, 12)


def fit_cell_term(
    cells: np.ndarray, basis: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> Tuple[float, np.ndarray]:
    """(residual ||D - sum_c lambda_c basis_c|| / ||K_o||, lambda (m,)): one unknown per cell,
    basis (m, 12, 12) in local node-major dofs, by least squares (LSQR, unit columns).
    """
    m, N = cells.shape[0], D.shape[0]
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(dof, 12, axis=1)
    cols = np.tile(dof, (1, 12))
    keys = rows.astype(np.int64) * N + cols
    pattern, where = np.unique(keys.ravel(), return_inverse=True)
    A = sp.csr_matrix(
        (basis.reshape(-1), (where.ravel(), np.repeat(np.arange(m), 144))),
        shape=(pattern.size, m),
    )
    Dc = sp.coo_matrix(D)
    dkeys = Dc.row.astype(np.int64) * N + Dc.col
    pos = np.searchsorted(pattern, dkeys)
    inside = (pos < pattern.size) & (pattern[np.minimum(pos, pattern.size - 1)] == dkeys)
    b = np.zeros(pattern.size)
    np.add.at(b, pos[inside], Dc.data[inside])
    outside = float(np.linalg.norm(Dc.data[~inside]))
    norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    norms[norms == 0] = 1.0
    sol = lsqr(A @ sp.diags(1.0 / norms), b, atol=1e-15, btol=1e-15, iter_lim=20 * m)
    lam = sol[0] / norms
    left = float(np.hypot(np.linalg.norm(A @ lam - b), outside))
    return left / float(sparse_norm(K_o)), lam


def fit_invariant_curvature(
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    D: sp.csr_matrix,
    K_o: sp.csr_matrix,
    invariant: str,
) -> Tuple[float, np.ndarray]:
    """(residual ||D - sum lambda_c V_c g_c g_c^T|| / ||K_o||, lambda (m,)) for ``invariant``."""
    return fit_cell_term(cells, curvature_basis(points, cells, x, invariant), D, K_o)


def second_derivative_findings(
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    K: sp.spmatrix,
    K_o: sp.spmatrix,
    tol: float,
) -> List[Finding]:
    """The invariants whose curvature term alone explains the stiffness error (the force being
    right); several are shown as ambiguous.
    """
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    if float(sparse_norm(D)) == 0.0:
        return []
    found = []
    for name in INVARIANTS:
        residual, lam = fit_invariant_curvature(points, cells, x, D, K_o, name)
        if residual <= tol and (name != "J" or _one_function_of_j(points, cells, x, lam)):
            found.append(_finding(name, residual, lam))
    for tensor in ("C^-1", "I"):
        basis = unsymmetrised_basis(points, cells, x, tensor)
        residual, lam = fit_cell_term(cells, basis, D, K_o)
        if residual <= tol:
            found.append(_unsymmetrised_finding(tensor, residual, lam))
    return ambiguous(found, "the invariants' gradients are parallel in this state")


def _one_function_of_j(points, cells, x, lam: np.ndarray) -> bool:
    """The J curvature's term dJ (x) dJ is J^2 C^-1 (x) C^-1: with a free factor per cell it
    also fits any other term along C^-1 (x) C^-1 (the isochoric projection's, in a decoupled
    tangent). Only a factor that is one function of J, on a state where J varies, is d2W/dJ2's.
    """
    J = np.linalg.det(cell_kinematics(points, cells, x)[2])
    steps = j_function_steps(J, lam)
    return bool(np.isfinite(steps) and steps <= j_function_line(J, lam))


def _finding(name: str, residual: float, lam: np.ndarray) -> Finding:
    q = np.percentile(lam, [0, 50, 100])
    return Finding(
        "tangent-curvature",
        f"material tangent: the term d2W/d{name}2 d{name} (x) d{name} is wrong (the second "
        f"derivative of W in {name} left out or changed, e.g. a function of {name} linearised "
        "in the tangent)",
        FULL,
        f"K - K_oracle = sum over cells of lambda_c V_c g_c g_c^T, g_c the gradient of {name} "
        f"over the cell's dofs, leaves a stiffness error of {residual:.1e}; fitted lambda_c "
        f"(engine minus oracle d2W/d{name}2) from {q[0]:.4g} to {q[2]:.4g} Pa, median "
        f"{q[1]:.4g}; the force matches",
        {"invariant": name, "residual": residual, "lambda_median": float(q[1])},
    )


def _unsymmetrised_finding(tensor: str, residual: float, lam: np.ndarray) -> Finding:
    q = np.percentile(lam, [0, 50, 100])
    return Finding(
        "tangent-unsymmetrised",
        f"material tangent: the {tensor} (.) {tensor} term of the elasticity tensor not "
        "symmetrised (its minor-symmetric half missing), contracted with the unsymmetrised "
        "variation F^T grad v of E",
        FULL,
        f"K - K_oracle = sum over cells of c_c V_c BL : ({tensor}_IK {tensor}_JL - "
        f"{tensor}_IL {tensor}_JK) / 2 : BL leaves a stiffness error of {residual:.1e}; fitted "
        f"c_c (the term's coefficient) from {q[0]:.4g} to {q[2]:.4g} Pa, median {q[1]:.4g}; "
        "the force matches",
        {"tensor": tensor, "residual": residual, "coefficient_median": float(q[1])},
    )


def second_derivative_reading(diag, ci, out, ref):
    """``diag`` (the force right, nothing explaining the stiffness) with the invariant whose
    curvature term explains it, first; unchanged when none does.
    """
    from dataclasses import replace

    tol = diag.tolerances
    if diag.errors.force > tol.force:
        return diag
    found = second_derivative_findings(
        ci.points, ci.cells, ci.positions, out.stiffness, ref.stiffness, tol.stiffness
    )
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
