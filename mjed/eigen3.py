"""Eigenvalues and eigenvectors of many symmetric 3x3 matrices at once, by cyclic Jacobi.

numpy.linalg.eigh calls LAPACK once per matrix: for 3x3 matrices the call overhead, not the
arithmetic, sets its cost (about 1 us per cell, most of Ogden's force). Jacobi's method
vectorises over cells instead: each rotation zeroes one off-diagonal entry of every cell at
once with a few dozen array operations, and a sweep rotates the three pairs. It converges
quadratically, is backward stable and keeps the eigenvectors orthonormal to round-off, so
the result is as exact as LAPACK's (tests/test_eigen3.py compares the two, near-repeated
eigenvalues included). Sweeps repeat until every cell's off-diagonal part is below round-off
of its diagonal (at most ``max_sweeps``; a rest state C = Id needs none).

Rotation formulas: Golub and Van Loan, Matrix Computations, section 8.5 (the symmetric
Schur decomposition), in the numerically stable form with t = tan(theta) of the smaller root.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

__all__ = ["symmetric_eigh"]

_PAIRS = ((0, 1), (0, 2), (1, 2))


def symmetric_eigh(A_t: np.ndarray, *, max_sweeps: int = 12) -> Tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition of symmetric matrices given component-major.

    Args:
        A_t: (3, 3, m) symmetric matrices, [i, j, cell] (only the upper triangle is read).
        max_sweeps: bound on the Jacobi sweeps (quadratic convergence needs 4 to 6).

    Returns:
        lam (m, 3) eigenvalues in ascending order and V (m, 3, 3) with V[:, :, n] the unit
        eigenvector of lam[:, n], as numpy.linalg.eigh returns them (eigenvector signs may
        differ).

    Raises:
        ValueError: a non-finite entry (the iteration would not converge).
    """
    if A_t.ndim != 3 or A_t.shape[:2] != (3, 3):
        raise ValueError(f"A_t must have shape (3, 3, m), got {A_t.shape}")
    if not np.isfinite(A_t).all():
        raise ValueError("symmetric_eigh: non-finite matrix entries")
    m = A_t.shape[-1]
    a = {(i, j): A_t[i, j].copy() for i in range(3) for j in range(i, 3)}  # upper triangle
    V = np.zeros((3, 3, m))
    for i in range(3):
        V[i, i] = 1.0
    # Converged when |off-diagonal| <= eps |diagonal| in every cell (Frobenius norms): the
    # eigenvalues are then exact to round-off (Weyl), as with LAPACK. One more sweep follows:
    # for separated eigenvalues it squares the residual (quadratic convergence); for
    # clustered ones, whose off-diagonal round-off cannot go further, it is harmless.
    tol = np.finfo(float).eps ** 2
    extra = 1
    for _ in range(max_sweeps):
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2
        diag = a[0, 0] ** 2 + a[1, 1] ** 2 + a[2, 2] ** 2
        if not (off > tol * diag).any():
            if extra == 0 or not off.any():
                break
            extra -= 1
        for p, q in _PAIRS:
            _rotate(a, V, p, q)
    else:
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2
        diag = a[0, 0] ** 2 + a[1, 1] ** 2 + a[2, 2] ** 2
        if (off > tol * diag).any():  # not seen in practice: quadratic convergence
            raise RuntimeError(f"symmetric_eigh: no convergence in {max_sweeps} sweeps")
    lam = np.stack([a[0, 0], a[1, 1], a[2, 2]], axis=1)  # (m, 3)
    order = np.argsort(lam, axis=1)
    lam = np.take_along_axis(lam, order, axis=1)
    V = np.take_along_axis(np.moveaxis(V, -1, 0), order[:, None, :], axis=2)
    return lam, V


def _rotate(a: dict, V: np.ndarray, p: int, q: int) -> None:
    """One Jacobi rotation in the (p, q) plane of every cell, in place: zeroes a_pq."""
    r = 3 - p - q  # the third index
    apq = a[p, q]
    diff = a[q, q] - a[p, p]
    # Where |a_pq| <= 1e-150 |a_qq - a_pp| the rotation angle is below 1e-150: a_pq is dropped
    # (it moves the eigenvalues by a_pq^2 / |a_qq - a_pp|, far below round-off). Elsewhere
    # |theta| <= 5e149, so theta^2 cannot overflow.
    skip = np.abs(apq) <= 1e-150 * np.abs(diff)
    theta = diff / (2.0 * np.where(skip, 1.0, apq))
    # t = sign(theta) / (|theta| + sqrt(theta^2 + 1)): the smaller root of t^2 + 2 theta t - 1.
    t = np.copysign(1.0, theta) / (np.abs(theta) + np.sqrt(theta * theta + 1.0))
    t[skip] = 0.0
    c = 1.0 / np.sqrt(t * t + 1.0)
    s = t * c
    tau = s / (1.0 + c)
    a[p, p] = a[p, p] - t * apq
    a[q, q] = a[q, q] + t * apq
    a[p, q] = np.zeros_like(apq)
    rp, rq = (min(r, p), max(r, p)), (min(r, q), max(r, q))
    arp, arq = a[rp], a[rq]
    a[rp] = arp - s * (arq + tau * arp)
    a[rq] = arq + s * (arp - tau * arq)
    vp, vq = V[:, p].copy(), V[:, q]
    V[:, p] -= s * (vq + tau * vp)
    V[:, q] += s * (vp - tau * vq)
