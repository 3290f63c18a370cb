"""The per-mesh maps of the compiled assembly and the CSR matrix it returns.

Compiled kernels sum each cell's edge blocks into one 3x3 block per mesh edge (U) and the
node blocks into Dg, then write every CSR entry once, in order (:func:`write_csr`). This
object holds the maps of one :class:`mjed.sparse.CSRPattern` and the U, Dg work arrays
(kept between calls: one field must not be evaluated from two threads at once).
"""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from mjed.sparse import CSRPattern

__all__ = ["CompiledAssembly"]


class CompiledAssembly:
    def __init__(self, pattern: CSRPattern, kernels):
        self.pattern = pattern
        self.cell_edges = np.ascontiguousarray(pattern.cell_edges, dtype=np.int64)
        self.cell_flip = np.ascontiguousarray(pattern.cell_flip, dtype=np.bool_)
        self.indptr = np.ascontiguousarray(pattern.indptr, dtype=np.int64)
        edges = np.ascontiguousarray(pattern.edges, dtype=np.int64)
        self.src, self.blkptr = kernels.block_sources(
            self.indptr,
            np.ascontiguousarray(pattern.indices, dtype=np.int64),
            edges,
            pattern.n_nodes,
        )
        self.U = np.zeros((pattern.n_edges, 3, 3))
        self.Dg = np.zeros((pattern.n_nodes, 3, 3))

    def arguments(self) -> Tuple[np.ndarray, ...]:
        """cell_edges, cell_flip, U, Dg, src, blkptr, indptr: the kernels' assembly arguments."""
        return self.cell_edges, self.cell_flip, self.U, self.Dg, self.src, self.blkptr, self.indptr

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix of ``data`` with this pattern; it owns its index arrays (as the NumPy
        engine's matrices do), so a caller may change it in place.
        """
        p = self.pattern
        K = sp.csr_matrix((data, p.indices.copy(), p.indptr.copy()), shape=p.shape, copy=False)
        K.has_sorted_indices = True
        return K
