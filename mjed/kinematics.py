"""Per-cell kinematics of P1 tetrahedra, as pure functions over arrays.

Shapes: m cells, 4 nodes per cell. F, C are (m, 3, 3); J, I1, I2 are (m,).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from mjed.eigen3 import symmetric_eigh

__all__ = ["deformation_gradient", "cofactor", "Kinematics"]


def deformation_gradient(x_cells: np.ndarray, D: np.ndarray) -> np.ndarray:
    """F = sum_a x_a (x) D_a.

    Args:
        x_cells: (m, 4, 3) current positions of each cell's nodes.
        D: (m, 4, 3) rest shape vectors.

    Returns:
        (m, 3, 3) deformation gradients.
    """
    return np.swapaxes(x_cells, 1, 2) @ D


def cofactor(F: np.ndarray) -> np.ndarray:
    """Cof F = dJ/dF = J F^-T, built from cross products so it stays finite at J <= 0.

    Args:
        F: (m, 3, 3).

    Returns:
        (m, 3, 3); column k is the cross product of the two other columns of F.
    """
    c0, c1, c2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)


class Kinematics:
    """Strain measures of every cell at one state, each computed on first use.

    Invariant functions of the materials read what they need from here, so a quantity used
    by several terms (C, I1, I2, ...) is computed once per evaluation; :meth:`memo` keeps
    any other per-state intermediate a term needs twice (e.g. Costa's fibre-frame strain).

    Besides the (m, 3, 3) arrays, ``Ft``, ``cof_t`` and ``C_t`` hold F, cof F and C
    component-major, (3, 3, m): batched 3x3 products are much faster in that layout (long
    contiguous rows instead of tiny trailing axes), so C and cof are computed there.

    Args:
        F: (m, 3, 3), or None when ``Ft`` is given (F is then formed on first use).
        Ft: (3, 3, m) F, component-major.
        cof_out, C_out: optional (3, 3, m) buffers for cof_t and C_t (the engine reuses them).
    """

    def __init__(
        self,
        F: "np.ndarray | None" = None,
        *,
        Ft: "np.ndarray | None" = None,
        cof_out: "np.ndarray | None" = None,
        C_out: "np.ndarray | None" = None,
    ):
        if F is None and Ft is None:
            raise ValueError("Kinematics needs F (m, 3, 3) or Ft (3, 3, m)")
        if F is not None:
            self.F = F
        if Ft is not None:
            self.Ft = Ft
        self._cof_out, self._C_out = cof_out, C_out
        self._memo: dict = {}

    @property
    def m(self) -> int:
        """Number of cells."""
        return self.Ft.shape[-1]

    def memo(self, key, compute):
        """compute() on the first call with ``key`` in this state, the kept result afterwards."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    @cached_property
    def F(self) -> np.ndarray:
        """(m, 3, 3) F."""
        return np.ascontiguousarray(np.moveaxis(self.Ft, -1, 0))

    @cached_property
    def Ft(self) -> np.ndarray:
        """(3, 3, m) F, component-major."""
        return np.ascontiguousarray(np.moveaxis(self.F, 0, -1))

    @cached_property
    def cof_t(self) -> np.ndarray:
        """(3, 3, m) cof F, component-major: cof_ij = F_(i+1)(j+1) F_(i+2)(j+2) - F_(i+1)(j+2)
        F_(i+2)(j+1).
        """
        A = self.Ft
        out = np.empty_like(A) if self._cof_out is None else self._cof_out
        for i in range(3):
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                np.multiply(A[i1, j1], A[i2, j2], out=out[i, j])
                out[i, j] -= A[i1, j2] * A[i2, j1]
        return out

    @cached_property
    def cof(self) -> np.ndarray:
        """(m, 3, 3) cofactor matrix J F^-T."""
        return np.ascontiguousarray(np.moveaxis(self.cof_t, -1, 0))

    @cached_property
    def J(self) -> np.ndarray:
        """(m,) det F, expanded along F's first column (only that column of cof F is formed
        unless cof_t is already there; the products are the same either way).
        """
        A = self.Ft
        if "cof_t" in self.__dict__:
            B = self.cof_t
            return A[0, 0] * B[0, 0] + A[1, 0] * B[1, 0] + A[2, 0] * B[2, 0]
        J = None
        for i in range(3):
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            c = A[i1, 1] * A[i2, 2]
            c -= A[i1, 2] * A[i2, 1]
            c *= A[i, 0]
            J = c if J is None else J + c
        return J

    @cached_property
    def C_t(self) -> np.ndarray:
        """(3, 3, m) C = F^T F, component-major: the six distinct entries by row products
        (about 3x faster than an einsum over the nine), mirrored.
        """
        A = self.Ft
        out = np.empty_like(A) if self._C_out is None else self._C_out
        tmp = np.empty(A.shape[-1])
        for i in range(3):
            for j in range(i, 3):
                o = out[i, j]
                np.multiply(A[0, i], A[0, j], out=o)
                for k in (1, 2):
                    np.multiply(A[k, i], A[k, j], out=tmp)
                    o += tmp
                if j != i:
                    out[j, i] = o
        return out

    @cached_property
    def C(self) -> np.ndarray:
        """(m, 3, 3) right Cauchy-Green tensor F^T F."""
        return np.ascontiguousarray(np.moveaxis(self.C_t, -1, 0))

    @cached_property
    def I1(self) -> np.ndarray:
        """(m,) tr C = sum_ij F_ij^2 (from F: the full C is not needed for it)."""
        F9 = self.Ft.reshape(9, -1)
        return np.einsum("km,km->m", F9, F9)

    @cached_property
    def I2(self) -> np.ndarray:
        """(m,) (I1^2 - tr C^2) / 2."""
        C = self.C_t.reshape(9, -1)
        return 0.5 * (self.I1**2 - np.einsum("km,km->m", C, C))

    @cached_property
    def E_t(self) -> np.ndarray:
        """(3, 3, m) Green-Lagrange strain (C - I) / 2, component-major."""
        E = 0.5 * self.C_t
        for i in range(3):
            E[i, i] -= 0.5
        return E

    @cached_property
    def trE(self) -> np.ndarray:
        """(m,) tr E = (I1 - 3) / 2."""
        E = self.E_t
        return E[0, 0] + E[1, 1] + E[2, 2]

    @cached_property
    def E(self) -> np.ndarray:
        """(m, 3, 3) Green-Lagrange strain (C - I) / 2."""
        E = 0.5 * self.C
        E[:, [0, 1, 2], [0, 1, 2]] -= 0.5
        return E

    @cached_property
    def eig(self) -> "tuple[np.ndarray, np.ndarray]":
        """Eigenvalues (m, 3), ascending, and eigenvectors (m, 3, 3) (columns) of C, by the
        vectorised Jacobi method of mjed.eigen3 (as exact as LAPACK, several times faster
        for many 3x3 matrices).
        """
        return symmetric_eigh(self.C_t)
