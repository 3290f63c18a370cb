"""Linear solver used by the implicit schemes: Jacobi-preconditioned conjugate gradients.

Written out (rather than scipy.sparse.linalg.cg) so that a loss of positive definiteness is
detected and reported: CG on an indefinite matrix can "converge" to nonsense or stall, and a
verification suite must say which happened.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CGResult", "conjugate_gradient"]


@dataclass(frozen=True)
class CGResult:
    """x: the solution (or last iterate); iterations; converged; reason: "converged",
    "max_iterations", "negative_curvature" (p^T A p <= 0: A is not positive definite) or
    "non_finite"; residual: final ||b - A x|| / ||b||."""

    x: np.ndarray
    iterations: int
    converged: bool
    reason: str
    residual: float


def conjugate_gradient(A, b: np.ndarray, *, tol: float = 1e-10, max_iterations: int = 1000, x0=None) -> CGResult:
    """Solve A x = b for a symmetric A, preconditioned by 1/diag(A).

    Args:
        A: (N, N) sparse or dense symmetric matrix.
        b: (N,).
        tol: relative residual ||r|| / ||b|| to reach.
    """
    b = np.asarray(b, dtype=float)
    nb = float(np.linalg.norm(b))
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    if nb == 0.0:
        return CGResult(x, 0, True, "converged", 0.0)
    d = np.asarray(A.diagonal(), dtype=float)
    inv_d = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 1.0)  # keep the preconditioner SPD
    r = b - A @ x
    z = inv_d * r
    p = z.copy()
    rz = float(r @ z)
    for k in range(1, max_iterations + 1):
        Ap = A @ p
        pAp = float(p @ Ap)
        if not np.isfinite(pAp):
            return CGResult(x, k, False, "non_finite", float(np.linalg.norm(r)) / nb)
        if pAp <= 0.0:
            return CGResult(x, k, False, "negative_curvature", float(np.linalg.norm(r)) / nb)
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        res = float(np.linalg.norm(r)) / nb
        if res <= tol:
            return CGResult(x, k, True, "converged", res)
        z = inv_d * r
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return CGResult(x, max_iterations, False, "max_iterations", float(np.linalg.norm(r)) / nb)
