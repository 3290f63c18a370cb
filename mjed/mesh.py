"""Linear tetrahedral meshes: validation and the rest-state quantities MJED needs.

For a P1 tetrahedron with rest vertices X_0..X_3 the deformation gradient is constant,
F = sum_a x_a (x) D_a, where the shape vectors D_a = grad N_a are computed once here from the
rest edge matrix. Everything the engine precomputes per mesh starts from these arrays.
"""

from __future__ import annotations

import warnings

import numpy as np

from mjed.errors import MeshError, MeshWarning

__all__ = ["TetMesh", "shape_vectors", "flat_cells"]

# Relative threshold under which a cell counts as flat: |6 V| <= tol * (longest edge)^3.
# A regular tet has |6 V| / l^3 = 0.118, a sliver from a good mesher rarely drops below 1e-4.
_DEGENERATE_TOL = 1e-10


def shape_vectors(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rest volumes and shape-function gradients of P1 tetrahedra.

    Args:
        points: (n, 3) rest positions.
        cells: (m, 4) node indices.

    Returns:
        signed_volume: (m,) signed volume det[X1-X0, X2-X0, X3-X0] / 6.
        D: (m, 4, 3) gradients of the barycentric shape functions, sum over a is zero.
    """
    X = points[cells]  # (m, 4, 3)
    edges = np.swapaxes(X[:, 1:, :] - X[:, :1, :], 1, 2)  # (m, 3, 3), columns X_a - X_0
    det = np.linalg.det(edges)
    D = np.empty((len(cells), 4, 3))
    nonflat = det != 0.0
    # Rows of the inverse edge matrix are grad N_1..N_3; N_0 = 1 - N_1 - N_2 - N_3.
    D[nonflat, 1:, :] = np.linalg.inv(edges[nonflat])
    D[~nonflat, 1:, :] = np.nan
    D[:, 0, :] = -D[:, 1:, :].sum(axis=1)
    return det / 6.0, D


class TetMesh:
    """A validated mesh of linear tetrahedra with its rest-state precomputation.

    Args:
        points: (n, 3) rest positions.
        cells: (m, 4) node indices, positively oriented (signed volume > 0).
        fix_orientation: if True, negatively oriented cells get two nodes swapped instead of
            raising; the number fixed is in ``n_reoriented`` and a MeshWarning says so.

    Attributes:
        points: (n, 3) float64, read-only.
        cells: (m, 4) int64, read-only (after any reorientation).
        volumes: (m,) rest volumes V0 (> 0).
        D: (m, 4, 3) shape vectors.
        n_reoriented: number of cells whose orientation was fixed.
        unreferenced_nodes: (k,) indices of nodes that no cell uses.

    Raises:
        MeshError: naming the offending cell or node.
    """

    def __init__(self, points, cells, *, fix_orientation: bool = False):
        points = _as_points(points)
        cells = _as_cells(cells, len(points))
        signed, D = shape_vectors(points, cells)

        flat = flat_cells(points, cells, signed)
        if flat.any():
            c = int(np.flatnonzero(flat)[0])
            raise MeshError(
                f"{int(flat.sum())} degenerate (zero-volume) cell(s); first is cell {c} with nodes "
                f"{cells[c].tolist()} and volume {signed[c]:.3e}"
            )

        negative = signed < 0
        self.n_reoriented = int(negative.sum())
        if self.n_reoriented:
            if not fix_orientation:
                c = int(np.flatnonzero(negative)[0])
                raise MeshError(
                    f"{self.n_reoriented} negatively oriented cell(s); first is cell {c} with "
                    f"nodes {cells[c].tolist()} and signed volume {signed[c]:.3e}. Pass "
                    "fix_orientation=True to swap two nodes of each such cell."
                )
            cells = cells.copy()
            cells[negative, 2], cells[negative, 3] = cells[negative, 3], cells[negative, 2].copy()
            signed, D = shape_vectors(points, cells)
            warnings.warn(
                f"reoriented {self.n_reoriented} cell(s) by swapping two nodes",
                MeshWarning,
                stacklevel=2,
            )

        used = np.zeros(len(points), dtype=bool)
        used[cells.ravel()] = True
        self.unreferenced_nodes = np.flatnonzero(~used)
        if len(self.unreferenced_nodes):
            k = self.unreferenced_nodes
            warnings.warn(
                f"{len(k)} node(s) belong to no cell (first: {k[:5].tolist()}); their rows of the "
                "stiffness matrix are empty",
                MeshWarning,
                stacklevel=2,
            )

        for a in (points, cells, signed, D):
            a.setflags(write=False)
        self.points = points
        self.cells = cells
        self.volumes = signed
        self.D = D

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def __repr__(self) -> str:
        return f"TetMesh(n_nodes={self.n_nodes}, n_cells={self.n_cells})"


def _as_points(points) -> np.ndarray:
    try:
        p = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"points must be a numeric (n, 3) array: {exc}") from None
    if p.ndim != 2 or p.shape[1] != 3:
        raise MeshError(f"points must have shape (n, 3), got {p.shape}")
    if len(p) < 4:
        raise MeshError(f"a tetrahedral mesh needs at least 4 points, got {len(p)}")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MeshError(
            f"{int(bad.sum())} node(s) with non-finite coordinates; first is node {i}: "
            f"{p[i].tolist()}"
        )
    return p


def _as_cells(cells, n_points: int) -> np.ndarray:
    c = np.asarray(cells)
    if c.ndim != 2 or c.shape[1] != 4:
        raise MeshError(f"cells must have shape (m, 4), got {c.shape}")
    if len(c) == 0:
        raise MeshError("the mesh has no cells")
    if not np.issubdtype(c.dtype, np.integer):
        if not (
            np.issubdtype(c.dtype, np.floating)
            and np.isfinite(c).all()
            and (c == np.round(c)).all()
        ):
            raise MeshError(f"cells must hold integer node indices, got dtype {c.dtype}")
    c = c.astype(np.int64)
    out = (c < 0) | (c >= n_points)
    if out.any():
        k = int(np.flatnonzero(out.any(axis=1))[0])
        raise MeshError(f"cell {k} has node indices out of range [0, {n_points}): {c[k].tolist()}")
    s = np.sort(c, axis=1)
    rep = (s[:, 1:] == s[:, :-1]).any(axis=1)
    if rep.any():
        k = int(np.flatnonzero(rep)[0])
        raise MeshError(f"cell {k} repeats a node: {c[k].tolist()}")
    return c


def flat_cells(points: np.ndarray, cells: np.ndarray, volumes: np.ndarray) -> np.ndarray:
    """(m,) bool: cells with |6 V| <= tol * (longest edge)^3, which no reordering can fix.

    points (n, 3); cells (m, 4); volumes (m,) signed or not. Relative to the cell's own
    size, so the test means the same at any length scale.
    """
    X = points[cells]
    i, j = np.triu_indices(4, k=1)
    longest = np.linalg.norm(X[:, i] - X[:, j], axis=2).max(axis=1)
    return np.abs(6.0 * volumes) <= _DEGENERATE_TOL * longest**3
