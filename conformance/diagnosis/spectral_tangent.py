"""A tangent of a sum of eigenvalue powers taken coaxial: the eigenvectors held fixed.

For P = tr C^q = sum_i lambda_i^q (Ogden's principal-stretch sums, q = alpha/2), dP/dC =
f(C) with f(lambda) = q lambda^(q-1), and its derivative in the principal frame N_i holds
f'(lambda_i) on the pairs i = i and the divided differences
theta_ij = (f(lambda_i) - f(lambda_j)) / (lambda_i - lambda_j) on the pairs i != j (the
rotation of the principal directions). An engine that differentiates f(C) with its
eigenvectors held fixed keeps the first and drops the second: per cell, its tangent lacks
4 dW/dP X, X_pqrs = sum_(i != j) theta_ij (N_pi N_qj N_ri N_sj + N_pi N_qj N_rj N_si) / 2, with
dW/dP unknown. The fit: one unknown per cell against the stiffness error
(:func:`conformance.diagnosis.second_derivative.fit_cell_term`); named when it leaves the
stiffness within the tolerance, the force being right.
"""

from __future__ import annotations

from typing import Any, List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.second_derivative import fit_cell_term

__all__ = ["power_exponent", "rotation_basis", "spectral_findings"]


def power_exponent(model: Any) -> Optional[float]:
    """Q of the model's eigenvalue power sum tr C^q (Ogden: alpha / 2), or None."""
    alpha = getattr(model, "alpha", None)
    if type(model).__name__ != "Ogden" or not isinstance(alpha, (int, float)) or alpha == 0:
        return None
    return 0.5 * float(alpha)


def rotation_basis(points, cells, x, q: float) -> np.ndarray:
    """(m, 12, 12): V0 sym(F^T grad v) : X : sym(F^T grad w) per cell, X the divided-difference
    part of d(tr C^q)'s second derivative (module docstring); equal eigenvalues take the limit
    f'(lambda).
    """
    V0, D, F = cell_kinematics(points, cells, x)
    lam, N = np.linalg.eigh(F.swapaxes(1, 2) @ F)
    f = q * lam ** (q - 1.0)
    df = q * (q - 1.0) * lam ** (q - 2.0)
    gap = lam[:, :, None] - lam[:, None, :]
    close = np.abs(gap) <= 1e-8 * np.abs(lam).max(axis=1)[:, None, None]
    theta = np.where(
        close, df[:, :, None], (f[:, :, None] - f[:, None, :]) / np.where(close, 1, gap)
    )
    theta = theta * (1.0 - np.eye(3))  # i != j only
    X = 0.5 * (
        np.einsum("mij,mpi,mqj,mri,msj->mpqrs", theta, N, N, N, N)
        + np.einsum("mij,mpi,mqj,mrj,msi->mpqrs", theta, N, N, N, N)
    )
    X = 0.5 * (X + X.swapaxes(1, 2))
    K = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, X, F, D)
    return (V0[:, None, None, None, None] * K).reshape(-1, 12, 12)


def spectral_findings(
    model: Any, points, cells, x, K: sp.spmatrix, K_o: sp.spmatrix, tol: float
) -> List[Finding]:
    """The coaxial-tangent finding when the per-cell fit explains K - K_o within ``tol``."""
    q = power_exponent(model)
    if q is None:
        return []
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    residual, lam = fit_cell_term(cells, rotation_basis(points, cells, x, q), D, K_o)
    if residual > tol:
        return []
    p = np.percentile(lam, [0, 50, 100])
    return [
        Finding(
            "tangent-coaxial",
            "coaxial tangent: the derivative of C^(alpha/2 - 1) taken with the eigenvectors "
            "held fixed (the divided differences between the eigenvalues, the rotation of the "
            "principal directions, dropped from your tangent)",
            FULL,
            "K - K_oracle = sum over cells of c_c V0 BL : X : BL, X the divided-difference "
            f"part of d2(tr C^{q:g})/dC2, leaves a stiffness error of {residual:.1e}; fitted c_c "
            f"from {p[0]:.4g} to {p[2]:.4g} Pa, median {p[1]:.4g}; the force matches",
            {"residual": residual, "coefficient_median": float(p[1])},
        )
    ]
