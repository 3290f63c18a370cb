"""The free-dof block of the implicit system matrix, assembled without sparse arithmetic.

The implicit Euler matrix A = a M + b K changes every step through K only, and its
constrained rows and columns are removed. Forming ``a * M + b * K`` and slicing
``A[free][:, free]`` allocates and re-sorts a new CSR three times a step. But the stiffness
of a mesh keeps one CSR pattern for the whole run, and M's entries lie inside it (a lumped
mass is diagonal, a consistent P1 mass couples the same node pairs as K), so both are done
once: :class:`FreeBlock` records, for each entry of the free block, where it comes from in
K's data array, and M's contribution on K's pattern. A step is then two vector operations and
one gather. A matrix K whose pattern differs (another mesh, an extra model with its own
entries) falls back to plain sparse arithmetic, with the same result.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp

__all__ = ["FreeBlock", "same_pattern", "sum_same_pattern", "values_on_pattern"]


def same_pattern(A: sp.csr_matrix, B: sp.csr_matrix) -> bool:
    """True if two CSR matrices store exactly the same (row, column) entries in the same order."""
    if A.shape != B.shape or A.nnz != B.nnz:
        return False
    if A.indptr is B.indptr and A.indices is B.indices:
        return True
    return np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)


def sum_same_pattern(A: sp.csr_matrix, B) -> sp.csr_matrix:
    """A + B as CSR; when both share one pattern, by adding their data arrays (no sorting)."""
    if sp.isspmatrix_csr(B) and same_pattern(A, B):
        return sp.csr_matrix((A.data + B.data, A.indices, A.indptr), shape=A.shape)
    return sp.csr_matrix(A + B)


def values_on_pattern(M, indptr, indices, shape) -> Optional[np.ndarray]:
    """M's entries laid on the CSR pattern (indptr, indices) of ``shape``: the (nnz,) array
    ``m`` with which ``a * m + b * K.data`` are the values of a M + b K for any K of that
    pattern; None when some entry of M lies outside the pattern.
    """
    indices = np.asarray(indices)
    nnz = len(indices)
    where = sp.csr_matrix((np.arange(1, nnz + 1, dtype=np.float64), indices, indptr), shape=shape)
    Mc = sp.csr_matrix(M).tocoo()
    pos = (
        np.asarray(where[Mc.row, Mc.col]).ravel().astype(np.int64) - 1
        if Mc.nnz
        else np.empty(0, np.int64)
    )
    if (pos < 0).any():
        return None
    on_pattern = np.zeros(nnz)
    np.add.at(on_pattern, pos, Mc.data)
    return on_pattern


class FreeBlock:
    """(a M + b K)[free][:, free] for a fixed M and a stiffness K of (usually) fixed pattern.

    Args:
        M: (N, N) sparse, constant.
        free: (F,) sorted indices of the unknowns kept.
    """

    def __init__(self, M, free: np.ndarray):
        self.M = sp.csr_matrix(M)
        self.free = np.asarray(free, dtype=np.int64)
        self._K_pattern: Optional[_Pattern] = None  # the structure the maps below belong to
        self._gather = self._indptr = self._indices = self._M_on_K = None
        self.M_ff = self.M[self.free][:, self.free]
        self.fast = False  # whether the last call used the precomputed maps

    def __call__(self, a: float, K: sp.csr_matrix, b: float) -> sp.csr_matrix:
        """The free block of a M + b K, CSR (F, F)."""
        K = sp.csr_matrix(K)
        if not K.has_canonical_format:
            K = K.copy()
            K.sum_duplicates()
        if self._K_pattern is None or not same_pattern(K, self._K_pattern):
            self._learn(K)
        if self._M_on_K is None:  # M is not inside K's pattern
            self.fast = False
            K_ff = K[self.free][:, self.free]
            return sp.csr_matrix(a * self.M_ff + b * K_ff)
        self.fast = True
        data = b * K.data
        data += a * self._M_on_K
        F = len(self.free)
        return sp.csr_matrix((data[self._gather], self._indices, self._indptr), shape=(F, F))

    def _learn(self, K: sp.csr_matrix) -> None:
        """Index maps from K's pattern to the free block, and M expressed on K's pattern."""
        # Copies: the maps must not follow a model that later rewrites its arrays in place.
        self._K_pattern = _Pattern(K.indptr.copy(), K.indices.copy(), K.shape)
        nnz = K.nnz
        # Each stored entry carries its own position (+1, so that none is zero); slicing keeps
        # stored entries, so the free block's data says where each of its entries came from.
        where = sp.csr_matrix(
            (np.arange(1, nnz + 1, dtype=np.float64), K.indices, K.indptr), shape=K.shape
        )
        block = where[self.free][:, self.free]
        block.sort_indices()
        self._gather = block.data.astype(np.int64) - 1
        self._indptr, self._indices = block.indptr, block.indices
        # Shared by every block returned from now on: read-only, so no consumer can corrupt them.
        self._indptr.setflags(write=False)
        self._indices.setflags(write=False)
        self._M_on_K = values_on_pattern(self.M, K.indptr, K.indices, K.shape)


class _Pattern:
    """Just the structure of a CSR matrix (for same_pattern)."""

    def __init__(self, indptr, indices, shape):
        self.indptr, self.indices, self.shape, self.nnz = indptr, indices, shape, len(indices)
