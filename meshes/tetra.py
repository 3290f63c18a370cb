"""Small NumPy helpers on linear tetrahedral meshes: volumes, orientation, compaction.

All functions are pure: they return new arrays and never modify their inputs.
"""

from __future__ import annotations

import numpy as np

from mjed.mesh import flat_cells

__all__ = ["signed_volumes", "orient_positively", "remove_unreferenced", "boundary_triangles"]

_FACES = np.array(
    [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
)  # outward for positively oriented cells


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volumes det[x1 - x0, x2 - x0, x3 - x0] / 6 of the cells.

    Args:
        points: (n, 3) node coordinates.
        cells: (m, 4) node indices.

    Returns:
        (m,) float64 signed volumes, positive for positively oriented cells.
    """
    x = np.asarray(points, dtype=np.float64)[np.asarray(cells)]  # (m, 4, 3)
    e1, e2, e3 = (x[:, k] - x[:, 0] for k in (1, 2, 3))
    # Triple product rather than np.linalg.det: same value, no (m, 3, 3) temporary.
    return np.einsum("ij,ij->i", np.cross(e1, e2), e3) / 6.0


def orient_positively(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, int]:
    """Swap two nodes of every negatively oriented cell.

    Args:
        points: (n, 3) node coordinates.
        cells: (m, 4) node indices.

    Returns:
        cells: (m, 4) int64 copy in which every cell has a positive signed volume.
        n_swapped: how many cells were reordered.

    Raises:
        ValueError: if a cell is flat (zero or near-zero volume); no reordering fixes that.
    """
    pts = np.asarray(points, dtype=np.float64)
    out = np.array(cells, dtype=np.int64, copy=True)
    vol = signed_volumes(pts, out)
    flat = flat_cells(pts, out, vol)  # the same test TetMesh applies
    if flat.any():
        k = int(np.flatnonzero(flat)[0])
        raise ValueError(
            f"{int(flat.sum())} flat (zero-volume) cell(s); first is cell {k} with nodes "
            f"{out[k].tolist()} and volume {vol[k]:.3e}"
        )
    negative = vol < 0
    # Swapping nodes 1 and 2 flips the sign of the triple product and keeps node 0 first.
    out[negative, 1], out[negative, 2] = out[negative, 2], out[negative, 1].copy()
    return out, int(negative.sum())


def remove_unreferenced(
    points: np.ndarray, cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop the nodes no cell uses and renumber the rest 0..k-1, keeping their order.

    Args:
        points: (n, d) node coordinates.
        cells: (m, c) node indices into ``points``.

    Returns:
        points: (k, d) float64 coordinates of the used nodes, in their original order.
        cells: (m, c) int64 indices into the new ``points``.
        n_removed: n - k.
    """
    pts = np.asarray(points, dtype=np.float64)
    c = np.asarray(cells, dtype=np.int64)
    used = np.zeros(len(pts), dtype=bool)
    used[c.ravel()] = True
    new_index = np.cumsum(used) - 1  # position of each used node among the used ones
    return pts[used].copy(), new_index[c].astype(np.int64), int(len(pts) - used.sum())


def boundary_triangles(cells: np.ndarray) -> np.ndarray:
    """Faces (k, 3) that belong to exactly one cell, oriented outwards for positive cells."""
    faces = np.asarray(cells)[:, _FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(
        np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True
    )
    return faces[counts[inverse.ravel()] == 1]
