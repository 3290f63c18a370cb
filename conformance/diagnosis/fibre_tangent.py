"""A fibre strain form's second derivative not symmetrised before the Voigt conversion.

Costa's Q = sum_ij B_ij (R^T E R)_ij^2 (R the per-cell frame, columns fibre, sheet, normal) has
d2Q/dCdC = sym(T), T_pqrs = 1/2 sum_ij B_ij R_pi R_qj R_ri R_sj: T is not minor-symmetric. An
engine that converts T itself to Voigt form (entries p <= q, r <= s) keeps
T_pqrs where (T_pqrs + T_pqsr) / 2 belongs: per cell its Voigt tangent is off by
c (T_pqrs - T_pqsr) in the shear columns, c = 2 dW/dQ unknown. The fit: one unknown per cell
against the stiffness error (:func:`conformance.diagnosis.second_derivative.fit_cell_term`),
through the engineering-shear B matrix; named when it leaves the stiffness within the
tolerance, the force being right.
"""

from __future__ import annotations

from typing import Any, List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.second_derivative import fit_cell_term

__all__ = ["VOIGT", "strain_form", "unsymmetrised_voigt_basis", "fibre_tangent_findings"]

#: Voigt order 11, 22, 33, 12, 23, 13.
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
_NAMES = (("b_ff", "b_fs", "b_fn"), ("b_fs", "b_ss", "b_sn"), ("b_fn", "b_sn", "b_nn"))


def strain_form(model: Any, m: int) -> Optional[tuple]:
    """(B (3, 3), R (m, 3, 3)): the model's fibre strain form and per-cell frame, or None."""
    frame = getattr(model, "frame", None)
    try:
        B = np.array([[float(getattr(model, n)) for n in row] for row in _NAMES])
    except (AttributeError, TypeError):
        return None
    R = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)  # None: the axes
    R = np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R.reshape(m, 3, 3)
    return B, R


def unsymmetrised_voigt_basis(points, cells, x, B: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(m, 12, 12) V0 Bv^T X Bv per cell, X_AB = T_pqrs - T_pqsr (A = pq, B = rs in Voigt
    order) and Bv the engineering-shear strain-displacement matrix.
    """
    V0, D, F = cell_kinematics(points, cells, x)
    T = 0.5 * np.einsum("ij,mpi,mqj,mri,msj->mpqrs", B, R, R, R, R)
    i = np.array([p[0] for p in VOIGT])
    j = np.array([p[1] for p in VOIGT])
    X = (T - T.swapaxes(3, 4))[:, i[:, None], j[:, None], i[None, :], j[None, :]]
    Bv = np.einsum("maj,mki->mijak", D, F)  # d E_ij-rate / d v_ak, unsymmetrised
    Bv = Bv + Bv.swapaxes(1, 2)
    Bv = Bv[:, i, j] * np.where(i == j, 0.5, 1.0)[None, :, None, None]  # engineering shear
    Bv = Bv.reshape(-1, 6, 12)
    return V0[:, None, None] * np.einsum("mAi,mAB,mBj->mij", Bv, X, Bv)


def fibre_tangent_findings(
    model: Any, points, cells, x, K: sp.spmatrix, K_o: sp.spmatrix, tol: float
) -> List[Finding]:
    """The unsymmetrised-d2Q finding when the per-cell fit explains K - K_o within ``tol``."""
    form = strain_form(model, cells.shape[0])
    if form is None:
        return []
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    residual, lam = fit_cell_term(cells, unsymmetrised_voigt_basis(points, cells, x, *form), D, K_o)
    if residual > tol:
        return []
    p = np.percentile(lam, [0, 50, 100])
    return [
        Finding(
            "tangent-fibre-unsymmetrised",
            "d2Q/dCdC of the fibre strain form not symmetrised in its last index pair before "
            "the Voigt conversion: your tangent is not minor-symmetric (its shear columns "
            "wrong)",
            FULL,
            "K - K_oracle = sum over cells of c_c V0 Bv^T X Bv, X_AB = T_pqrs - T_pqsr the "
            "unsymmetrised part of d2Q/dC2 in Voigt order, leaves a stiffness error of "
            f"{residual:.1e}; fitted c_c from {p[0]:.4g} to {p[2]:.4g} Pa, median {p[1]:.4g}; "
            "the force matches",
            {"residual": residual, "coefficient_median": float(p[1])},
        )
    ]
