"""The fixed CSR pattern of a tetrahedral mesh and the element-to-CSR scatter map.

Both depend only on the connectivity, so they are computed once; each assembly is then a
single weighted bincount of the element matrices into the CSR data array.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["element_dofs", "CSRPattern"]


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """Global dofs of each cell, dof = 3 * node + component.

    Args:
        cells: (m, 4).

    Returns:
        (m, 12) int64, ordered (node 0: x, y, z, node 1: x, y, z, ...).
    """
    return (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12).astype(np.int64)


class CSRPattern:
    """Sparsity pattern of the (3n, 3n) stiffness and where each element entry lands in it.

    Attributes:
        indptr, indices: the CSR structure (sorted column indices).
        scatter: (m * 144,) position in the data array of each entry of the (m, 12, 12)
            element matrices, in C order.
        force_scatter: (m * 12,) global dof of each entry of the (m, 4, 3) element forces.
    """

    def __init__(self, cells: np.ndarray, n_nodes: int):
        dofs = element_dofs(cells)
        n = 3 * n_nodes
        self.shape = (n, n)
        keys = (dofs[:, :, None] * n + dofs[:, None, :]).ravel()
        unique, self.scatter = np.unique(keys, return_inverse=True)
        self.scatter = self.scatter.astype(np.intp)
        rows = unique // n
        self.indices = (unique - rows * n).astype(np.int32 if n < 2**31 else np.int64)
        self.indptr = np.zeros(n + 1, dtype=self.indices.dtype)
        np.cumsum(np.bincount(rows, minlength=n), out=self.indptr[1:])
        self.force_scatter = dofs.ravel()
        self.n_dofs = n

    @property
    def nnz(self) -> int:
        return len(self.indices)

    def assemble_matrix(self, element_matrices: np.ndarray) -> sp.csr_matrix:
        """Sum (m, 12, 12) element matrices into a CSR matrix with this pattern."""
        data = np.bincount(self.scatter, weights=element_matrices.reshape(-1), minlength=self.nnz)
        return sp.csr_matrix((data, self.indices.copy(), self.indptr.copy()), shape=self.shape)

    def assemble_vector(self, element_vectors: np.ndarray) -> np.ndarray:
        """Sum (m, 4, 3) element vectors into an (n, 3) nodal array."""
        out = np.bincount(self.force_scatter, weights=element_vectors.reshape(-1), minlength=self.n_dofs)
        return out.reshape(-1, 3)
