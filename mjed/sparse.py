"""The fixed CSR pattern of a tetrahedral mesh and the scatter maps into it.

Everything here depends only on the connectivity, so it is computed once per mesh; each
assembly is then one weighted ``np.bincount`` with a precomputed index map plus one gather.

Two routes into the same CSR data array:

- ``assemble_edge_blocks``: the six 3x3 edge blocks K_ab (a < b) of every cell. Blocks of
  cells sharing a mesh edge are summed per edge (54 numbers per cell instead of 144); the
  node (diagonal) blocks follow from translation invariance, K_ii = -sum_{j != i} K_ij,
  which holds for the assembled matrix because it holds cell by cell. This is the route of
  MJED (and of SOFA's tetrahedral hyperelastic force fields, which store edge stiffnesses).
- ``assemble_matrix``: general (m, 12, 12) element matrices, no assumption on them.
"""

from __future__ import annotations

from typing import Dict, Tuple

import numpy as np
import scipy.sparse as sp

__all__ = ["EDGES", "element_dofs", "CSRPattern"]

#: The six edges (a, b), a < b, of a tetrahedron (the order of the engine's edge axis).
EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """Global dofs of each cell, dof = 3 * node + component.

    Args:
        cells: (m, 4).

    Returns:
        (m, 12) int64, ordered (node 0: x, y, z, node 1: x, y, z, ...).
    """
    return (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12).astype(np.int64)


class CSRPattern:
    """Sparsity pattern of the (3n, 3n) stiffness and where element entries land in it.

    Built from the unique mesh edges (memory O(m), no per-entry sort), so it scales to
    millions of cells.

    Attributes:
        indptr, indices: the CSR structure (sorted column indices), read-only; every node
            has its diagonal block (explicit zeros for nodes no cell uses).
        edges: (E, 2) unique mesh edges (i < j).
        cell_edges: (m, 6) edge index of each cell edge (EDGES order).
        cell_flip: (m, 6) True where the cell edge (a, b) runs from j to i.
        force_scatter: (m * 12,) global dof of each entry of (m, 4, 3) element vectors.
    """

    def __init__(self, cells: np.ndarray, n_nodes: int):
        cells = np.asarray(cells, dtype=np.int64)
        self.cells = cells
        self.n_nodes = n = int(n_nodes)
        self.n_dofs = 3 * n
        self.shape = (3 * n, 3 * n)
        m = len(cells)
        a, b = cells[:, EDGES[:, 0]], cells[:, EDGES[:, 1]]  # (m, 6)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        keys = lo * n + hi
        uniq, inverse = np.unique(keys.ravel(), return_inverse=True)
        self.edges = np.stack([uniq // n, uniq % n], axis=1)
        self.cell_edges = inverse.reshape(m, 6).astype(np.intp)
        self.cell_flip = a > b
        E = len(uniq)
        self.n_edges = E

        # Node-level pattern: both orientations of every edge plus the diagonal, row-major.
        i, j = self.edges[:, 0], self.edges[:, 1]
        node_rows = np.concatenate([i, j, np.arange(n)])
        node_cols = np.concatenate([j, i, np.arange(n)])
        # Source of each node block in the stacked array [U (E) ; U^T (E) ; diag (n)].
        order = np.lexsort((node_cols, node_rows))
        node_rows, node_cols = node_rows[order], node_cols[order]
        self._node_keys = node_rows * n + node_cols  # sorted
        self._node_source = order  # 0..E-1 upper, E..2E-1 transposed, 2E.. diagonal
        deg = np.bincount(node_rows, minlength=n)
        nodeptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(deg, out=nodeptr[1:])
        self._nodeptr, self._deg = nodeptr, deg
        nnz = 9 * len(node_rows)
        itype = np.int32 if max(nnz, 3 * n) < 2**31 else np.int64
        # Row 3 i + r holds, for each neighbour k (sorted), the three columns 3 k + c.
        indptr = np.zeros(3 * n + 1, dtype=np.int64)
        np.cumsum(np.repeat(3 * deg, 3), out=indptr[1:])
        self.indptr = indptr.astype(itype)
        self.indices = self._expand_columns(node_cols).astype(itype)
        self.indptr.setflags(write=False)
        self.indices.setflags(write=False)
        self.force_scatter = element_dofs(cells).ravel()
        self._maps: Dict[object, object] = {}  # index maps and scatter matrices, keyed by layout
        self._gather: "np.ndarray | None" = None
        self._diag_index: "np.ndarray | None" = None
        self._scatter: "np.ndarray | None" = None

    @property
    def nnz(self) -> int:
        return len(self.indices)

    # ------------------------------------------------------------ pattern construction
    def _entry_positions(self) -> np.ndarray:
        """(P, 3, 3) position in the CSR data array of entry (r, c) of each node block, P in
        node-pattern order (row i, then sorted neighbour k): rows 3 i + r hold, for each
        neighbour k, the three columns 3 k + c.
        """
        nodeptr, deg = self._nodeptr, self._deg
        rows = np.repeat(np.arange(self.n_nodes), deg)
        k = np.arange(len(rows)) - nodeptr[rows]
        pos0 = 9 * nodeptr[rows] + 3 * k
        row_len = 3 * deg[rows]
        return (
            pos0[:, None, None]
            + np.arange(3)[None, :, None] * row_len[:, None, None]
            + np.arange(3)[None, None, :]
        )

    def _expand_columns(self, node_cols: np.ndarray) -> np.ndarray:
        """CSR column indices of the 3x3-block expansion of the node pattern."""
        pos = self._entry_positions()
        cols = np.empty(9 * len(node_cols), dtype=np.int64)
        cols[pos] = 3 * node_cols[:, None, None] + np.arange(3)[None, None, :]
        return cols

    def _block_positions(self, rows: np.ndarray, cols: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Position in the CSR data array of entry (0, 0) of node block (rows, cols) and the
        row length; entry (r, c) is at pos + r * row_len + c.
        """
        p = np.searchsorted(self._node_keys, rows * self.n_nodes + cols)
        k = p - self._nodeptr[rows]
        row_len = 3 * self._deg[rows]
        return 9 * self._nodeptr[rows] + 3 * k, row_len

    # ------------------------------------------------------------ edge-block route
    def edge_block_map(self, layout: str = "merc") -> np.ndarray:
        """Index of every edge-block entry in the (3, 3, E) edge sums, for blocks stored with
        axes in ``layout`` order (m cell, e edge, r row, c column), e.g. "merc" for
        (m, 6, 3, 3) or "rcem" for (3, 3, 6, m) (named in mjed.layout.BlockLayout). Cached
        per layout.
        """
        if layout not in self._maps:
            if sorted(layout) != sorted("merc"):
                raise ValueError(f"layout must be a permutation of 'merc', got {layout!r}")
            E = self.n_edges
            r = np.arange(3)[None, None, :, None]
            c = np.arange(3)[None, None, None, :]
            flip = self.cell_flip[:, :, None, None]
            # A flipped cell edge holds the block of (j, i): its (r, c) is the edge's (c, r).
            target = np.where(flip, c * 3 + r, r * 3 + c) * E + self.cell_edges[:, :, None, None]
            axes = ["merc".index(ax) for ax in layout]
            self._maps[layout] = (
                np.ascontiguousarray(np.transpose(target, axes)).ravel().astype(np.intp)
            )
        return self._maps[layout]

    def _edge_gather(self) -> Tuple[np.ndarray, np.ndarray]:
        """Maps from the edge sums to the node diagonal and to the CSR data array."""
        if self._gather is None:
            E, n = self.n_edges, self.n_nodes
            i, j = self.edges[:, 0], self.edges[:, 1]
            rc = np.arange(9)
            r, c = rc // 3, rc % 3
            # K_ii -= U_e and K_jj -= U_e^T for every edge e = (i, j); diag stored (3, 3, n).
            to_i = (r * 3 + c)[:, None] * n + i[None, :]
            to_j = (c * 3 + r)[:, None] * n + j[None, :]
            self._diag_index = np.concatenate([to_i.ravel(), to_j.ravel()]).astype(np.intp)
            # Sources in the stacked vector [U (9 E) ; diag (9 n)].
            src = self._node_source
            upper, lower = src < E, (src >= E) & (src < 2 * E)
            blk = np.empty((len(src), 3, 3), dtype=np.int64)
            e_up, e_lo, d = src[upper], src[lower] - E, src[~upper & ~lower] - 2 * E
            blk[upper] = (r * 3 + c).reshape(3, 3)[None] * E + e_up[:, None, None]
            blk[lower] = (c * 3 + r).reshape(3, 3)[None] * E + e_lo[:, None, None]
            blk[~upper & ~lower] = 9 * E + (r * 3 + c).reshape(3, 3)[None] * n + d[:, None, None]
            gather = np.empty(self.nnz, dtype=np.intp)
            gather[self._entry_positions()] = blk
            self._gather = gather
        return self._gather, self._diag_index

    def assemble_edge_blocks(self, blocks: np.ndarray, layout: str = "merc") -> sp.csr_matrix:
        """Sum the edge blocks of every cell into a CSR matrix with this pattern.

        Args:
            blocks: the (a < b) blocks d2W/dx_a dx_b of every cell, (m, 6, 3, 3) for layout
                "merc" or any axis permutation of it named by ``layout``.

        The node blocks are -sum of the row's edge blocks (translation invariance).
        """
        gather, diag_index = self._edge_gather()
        E, n = self.n_edges, self.n_nodes
        U = np.bincount(self.edge_block_map(layout), weights=blocks.reshape(-1), minlength=9 * E)
        diag = np.bincount(diag_index, weights=np.concatenate([U, U]), minlength=9 * n)
        np.negative(diag, out=diag)
        data = np.concatenate([U, diag])[gather]
        return self._csr(data)

    def edge_scalar_matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The node-level (n, n) CSR matrix L of one scalar per cell edge: L_ab sums values
        over the cells' edges (a, b) (both orientations), L_aa = -sum_b L_ab.

        Args:
            values: (m, 6) one scalar per cell edge (a, b) of mjed.sparse.EDGES.

        L (x) Id is the (3n, 3n) matrix whose edge blocks are values * Id (node blocks by
        translation invariance, as in assemble_edge_blocks); :meth:`add_scalar_blocks` adds
        it into a data array of this pattern. A stiffness of this form is that of a constant
        stress Q, blocks V (D_a . Q D_b) Id; such a body's energy is quadratic in x, so that
        is its whole tangent and its force is -(L @ x).
        """
        values = np.asarray(values, dtype=float)
        if values.shape != self.cell_edges.shape:
            raise ValueError(f"values must be (m, 6) = {self.cell_edges.shape}, got {values.shape}")
        E, n = self.n_edges, self.n_nodes
        U = np.bincount(self.cell_edges.ravel(), weights=values.ravel(), minlength=E)
        diag = np.bincount(self.edges[:, 0], weights=U, minlength=n) + np.bincount(
            self.edges[:, 1], weights=U, minlength=n
        )
        src = (
            self._node_source
        )  # node-pattern order: 0..E-1 upper, E..2E-1 transposed, 2E.. diagonal
        data = np.concatenate([U, -diag])[np.where(src < E, src, src - E)]
        indptr = self._nodeptr.astype(self.indptr.dtype)
        indices = (self._node_keys % n).astype(self.indices.dtype)
        L = sp.csr_matrix((data, indices, indptr), shape=(n, n), copy=False)
        L.has_sorted_indices = True
        return L

    def add_scalar_blocks(self, data: np.ndarray, L: sp.csr_matrix) -> None:
        """Data += the entries of L (x) Id, in place: data is the value array of a CSR matrix
        with this pattern and L comes from :meth:`edge_scalar_matrix` (same node pattern).
        """
        if L.nnz != len(self._node_keys) or len(data) != self.nnz:
            raise ValueError(
                f"L must come from edge_scalar_matrix of this pattern ({len(self._node_keys)} "
                f"entries, got {L.nnz}) and data must have {self.nnz} entries (got {len(data)})"
            )
        key = "diag"
        if key not in self._maps:
            pos = self._entry_positions()
            self._maps[key] = np.ascontiguousarray(
                np.stack([pos[:, r, r] for r in range(3)], axis=1)
            )  # (P, 3)
        data[self._maps[key]] += L.data[:, None]

    # ------------------------------------------------------------ general route
    @property
    def scatter(self) -> np.ndarray:
        """(m * 144,) position in the data array of each entry of (m, 12, 12) element
        matrices, in C order (built on first use: 144 indices per cell).
        """
        if self._scatter is None:
            cells = self.cells
            m = len(cells)
            rows = np.repeat(cells, 4, axis=1)  # (m, 16): node a for pair (a, b)
            cols = np.tile(cells, (1, 4))
            pos, row_len = self._block_positions(rows.ravel(), cols.ravel())
            pos, row_len = pos.reshape(m, 4, 1, 4, 1), row_len.reshape(m, 4, 1, 4, 1)
            r = np.arange(3)[None, None, :, None, None]
            c = np.arange(3)[None, None, None, None, :]
            self._scatter = (pos + r * row_len + c).reshape(m * 144).astype(np.intp)
        return self._scatter

    def assemble_matrix(self, element_matrices: np.ndarray) -> sp.csr_matrix:
        """Sum (m, 12, 12) element matrices into a CSR matrix with this pattern."""
        data = np.bincount(self.scatter, weights=element_matrices.reshape(-1), minlength=self.nnz)
        return self._csr(data)

    def assemble_vector(self, element_vectors: np.ndarray) -> np.ndarray:
        """Sum (m, 4, 3) element vectors into an (n, 3) nodal array."""
        out = np.bincount(
            self.force_scatter, weights=element_vectors.reshape(-1), minlength=self.n_dofs
        )
        return out.reshape(-1, 3)

    def vector_map(self, layout: str = "mak") -> np.ndarray:
        """Global dof of each entry of element vectors stored with axes in ``layout`` order
        (m cell, a node, k component), e.g. "kam" for (3, 4, m) (named in
        mjed.layout.VectorLayout). Cached.
        """
        key = ("vec", layout)
        if key not in self._maps:
            if sorted(layout) != sorted("mak"):
                raise ValueError(f"layout must be a permutation of 'mak', got {layout!r}")
            dofs = element_dofs(self.cells).reshape(-1, 4, 3)
            axes = ["mak".index(ax) for ax in layout]
            self._maps[key] = np.ascontiguousarray(np.transpose(dofs, axes)).ravel().astype(np.intp)
        return self._maps[key]

    def vector_scatter(self, layout: str = "mak") -> sp.csr_matrix:
        """The (3n, 12m) 0/1 matrix summing element vectors stored in ``layout`` order into
        nodal dofs. A sparse matrix-vector product with it is about twice as fast as a
        weighted bincount (it reads each row's entries contiguously). Cached per layout.
        """
        key = ("scatter", layout)
        if key not in self._maps:
            dofs = self.vector_map(layout)
            self._maps[key] = sp.csr_matrix(
                (np.ones(len(dofs)), (dofs, np.arange(len(dofs)))), shape=(self.n_dofs, len(dofs))
            )
        return self._maps[key]

    def assemble_vector_layout(self, element_vectors: np.ndarray, layout: str) -> np.ndarray:
        """Like assemble_vector, for element vectors stored with axes in ``layout`` order."""
        if element_vectors.size != 12 * len(self.cells):
            raise ValueError(
                f"element vectors must hold 12 values per cell ({12 * len(self.cells)}), got shape "
                f"{element_vectors.shape}"
            )
        return (self.vector_scatter(layout) @ element_vectors.reshape(-1)).reshape(-1, 3)

    def _csr(self, data: np.ndarray) -> sp.csr_matrix:
        # Each matrix gets its own copy of the index arrays (50 us on cube-paper), so a caller
        # may change it in place (eliminate_zeros, boundary rows) without touching the pattern.
        K = sp.csr_matrix(
            (data, self.indices.copy(), self.indptr.copy()), shape=self.shape, copy=False
        )
        K.has_sorted_indices = True
        return K
