"""Renumber a CSR matrix assembled in dolfinx's dof order into the input dof order.

PETSc returns the same sparsity pattern on every assembly into the same matrix, so the
reordering of the value array is computed once per pattern and then costs one gather.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

__all__ = ["CSRRenumbering"]


class CSRRenumbering:
    """Maps CSR triples (indptr, indices, data) in dof order to a (N, N) input-order matrix.

    Args:
        new_index_of_old: (n_old,) input dof index of each dolfinx dof (the map need not be
            onto: input dofs of unused nodes get empty rows and columns).
        size: N, the number of input dofs (3 n).
    """

    def __init__(self, new_index_of_old: np.ndarray, size: int):
        self._new = np.asarray(new_index_of_old, dtype=np.int64)
        self._size = int(size)
        self._pattern: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._order: Optional[np.ndarray] = None
        self._indptr: Optional[np.ndarray] = None
        self._indices: Optional[np.ndarray] = None

    def _prepare(self, indptr: np.ndarray, indices: np.ndarray) -> None:
        rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
        new_rows = self._new[rows]
        new_cols = self._new[indices]
        order = np.lexsort((new_cols, new_rows))  # row-major, columns sorted within a row
        counts = np.bincount(new_rows, minlength=self._size)
        self._indptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        self._indices = new_cols[order]
        self._order = order
        self._pattern = (indptr.copy(), indices.copy())

    def __call__(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> sp.csr_matrix:
        """The renumbered matrix as scipy CSR, shape (N, N), sorted indices, no duplicates."""
        if self._pattern is None or not (
            np.array_equal(self._pattern[0], indptr) and np.array_equal(self._pattern[1], indices)
        ):
            self._prepare(np.asarray(indptr), np.asarray(indices))
        return sp.csr_matrix(
            (data[self._order], self._indices.copy(), self._indptr.copy()),
            shape=(self._size, self._size),
        )
