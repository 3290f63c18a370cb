"""Costa's fibre-frame quadratic form as an MJED invariant function.

    g = Q = sum_ij B_ij (Ef)_ij^2,  Ef = R^T E R,  E = (C - I)/2,
    S = 2 dQ/dC = 2 R (B o Ef) R^T        (o: entrywise product)
    dS/dC : H = R (B o (R^T H R)) R^T.

The entrywise product is not of MJED's (gamma, B) form as it stands. Writing B as a signed sum
of rank-one terms, B = sum_i s_i d_i d_i^T (s_i = +-1), gives B o X = sum_i s_i diag(d_i) X
diag(d_i),
so the tangent becomes three second-kind pairs with the constant matrices R diag(d_i) R^T.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Tuple

import numpy as np

from mjed.terms import InvariantFunction, TangentPair

__all__ = ["signed_split", "FibreQuadratic"]


def signed_split(B: np.ndarray, method: str = "ldl") -> Tuple[np.ndarray, np.ndarray]:
    """Signs s (k,) and vectors d (k, 3) with B = sum_i s_i d_i d_i^T.

    method "ldl": the signed Cholesky (L D L^T) factorisation used by SOFA's MJED Costa; each
    pivot's sign is kept, so an indefinite remainder is handled, but a zero pivot before the
    last one divides by zero and is refused. method "eigen": the eigendecomposition, which
    exists for every symmetric B.
    """
    B = np.asarray(B, dtype=float)
    if method == "eigen":
        lam, V = np.linalg.eigh(B)
        keep = lam != 0.0
        return np.sign(lam[keep]), (np.sqrt(np.abs(lam[keep])) * V[:, keep]).T
    if method != "ldl":
        raise ValueError(f"unknown split method {method!r}; use 'ldl' or 'eigen'")
    L = np.eye(3)
    pivots = np.zeros(3)
    A = B.copy()
    for k in range(3):
        pivots[k] = A[k, k]
        if k < 2:
            if pivots[k] == 0.0:
                names = ("b_ff", "b_ss - b_fs^2/b_ff")
                raise ValueError(
                    f"Costa: the signed L D L^T split of B divides by zero: pivot {k + 1} "
                    f"({names[k]}) is zero. Perturb the b parameters or use split='eigen'."
                )
            L[k + 1 :, k] = A[k + 1 :, k] / pivots[k]
            A[k + 1 :, k + 1 :] -= np.outer(L[k + 1 :, k], A[k, k + 1 :])
    keep = pivots != 0.0
    return np.sign(pivots[keep]), (np.sqrt(np.abs(pivots[keep])) * L[:, keep]).T


def _frame_product(R: np.ndarray) -> "np.ndarray | None":
    """K (9, 9) with vec(R^T X R) = vec(X) K for a constant frame R (3, 3), K[ij, pq] = R_ip R_jq;
    None for the identity frame (nothing to rotate).
    """
    if np.array_equal(R, np.eye(3)):
        return None
    return np.einsum("ip,jq->ijpq", R, R).reshape(9, 9)


def _to_frame(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """R^T X R for X (m, 3, 3): one (m, 9) x (9, 9) product for a constant R (a batched 3x3
    matmul would loop per cell and dominate Costa's cost), a batched product per cell frame.
    """
    if R.ndim == 3:
        return np.swapaxes(R, -1, -2) @ X @ R
    K = _frame_product(R)
    return X if K is None else (X.reshape(-1, 9) @ K).reshape(-1, 3, 3)


def _from_frame(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """R X R^T for X (m, 3, 3), the inverse of :func:`_to_frame`."""
    if R.ndim == 3:
        return R @ X @ np.swapaxes(R, -1, -2)
    K = _frame_product(R)
    return X if K is None else (X.reshape(-1, 9) @ K.T).reshape(-1, 3, 3)


@dataclass(frozen=True, eq=False)
class FibreQuadratic(InvariantFunction):
    """g = sum_ij B_ij (R^T E R)_ij^2 for a constant symmetric B and frame R.

    B: (3, 3). R: (3, 3) or (m, 3, 3) orthonormal, columns fibre, sheet, normal.
    """

    B: np.ndarray
    R: np.ndarray
    split: str = "ldl"
    tangent: Tuple[TangentPair, ...] = field(init=False)
    signs: np.ndarray = field(init=False)

    def __post_init__(self):
        s, d = signed_split(self.B, self.split)
        if self.R.ndim == 2:
            mats = [self.R @ np.diag(di) @ self.R.T for di in d]
        else:
            mats = [np.einsum("mij,j,mkj->mik", self.R, di, self.R) for di in d]
        object.__setattr__(self, "tangent", tuple(TangentPair("second", M) for M in mats))
        object.__setattr__(self, "signs", s)

    def _Ef(self, kin) -> np.ndarray:
        """R^T E R, (m, 3, 3), computed once per state (value and stress both need it)."""
        return kin.memo(("fibre strain", id(self)), lambda: _to_frame(kin.E, self.R))

    def value(self, kin):
        Ef = self._Ef(kin)
        return np.einsum("ij,mij->m", self.B, Ef * Ef)

    def stress(self, kin):
        return 2.0 * _from_frame(self.B * self._Ef(kin), self.R)

    def tangent_coefficients(self, kin):
        return tuple(float(s) for s in self.signs)
