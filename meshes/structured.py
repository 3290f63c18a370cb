"""A fast structured tetrahedral mesh of a box, for scaling studies (no gmsh).

Each of the n_x n_y n_z hexahedra is cut into six tetrahedra around its main diagonal
(the Kuhn, or Freudenthal, subdivision): one tetrahedron per ordering of the three axes,
walking from the cube's corner (0, 0, 0) to (1, 1, 1) one axis at a time. Every hexahedron
uses the same diagonal direction, so the faces of neighbouring hexahedra match and the
mesh is conforming. Building a million cells takes well under a second.
"""

from __future__ import annotations

from itertools import permutations
from typing import Sequence, Tuple, Union

import numpy as np

__all__ = ["structured_box", "cube_with_cells"]

# The six axis orderings and, for each, the sign of the tetrahedron it gives
# (det of the three steps = sign of the permutation); odd ones get two vertices swapped.
_PERMS = np.array(list(permutations(range(3))))


def _kuhn_offsets() -> np.ndarray:
    """(6, 4, 3) corner offsets (0/1) of the six positively oriented tetrahedra."""
    out = np.zeros((6, 4, 3), dtype=np.int64)
    for t, perm in enumerate(_PERMS):
        corner = np.zeros(3, dtype=np.int64)
        for step, axis in enumerate(perm, start=1):
            corner = corner.copy()
            corner[axis] = 1
            out[t, step] = corner
        edges = out[t, 1:] - out[t, 0]
        if np.linalg.det(edges.astype(float)) < 0:
            out[t, [1, 2]] = out[t, [2, 1]]
    return out


def structured_box(
    divisions: Union[int, Sequence[int]], lengths: Sequence[float] = (1.0, 1.0, 1.0)
) -> Tuple[np.ndarray, np.ndarray]:
    """Points and positively oriented cells of a box [0, Lx] x [0, Ly] x [0, Lz].

    Args:
        divisions: hexahedra per axis, one int for all three or (n_x, n_y, n_z), each >= 1.
        lengths: box edge lengths, each > 0.

    Returns:
        points (prod(n + 1), 3) float64 and cells (6 prod(n), 4) int64.

    Raises:
        ValueError: naming a bad division count or length.
    """
    n = np.broadcast_to(np.asarray(divisions), (3,))
    if n.dtype.kind not in "iu" or np.any(n < 1):
        raise ValueError(f"divisions must be integers >= 1, got {divisions!r}")
    L = np.asarray(lengths, dtype=float)
    if L.shape != (3,) or not np.all(np.isfinite(L)) or np.any(L <= 0):
        raise ValueError(f"lengths must be three finite positive numbers, got {lengths!r}")
    nx, ny, nz = (int(v) for v in n)
    axes = [np.linspace(0.0, L[k], int(n[k]) + 1) for k in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # (h, 3) lower corner of each hex
    off = _kuhn_offsets()  # (6, 4, 3)
    corners = base[:, None, None, :] + off[None]  # (h, 6, 4, 3)
    cells = node(corners[..., 0], corners[..., 1], corners[..., 2]).reshape(-1, 4)
    return points, cells.astype(np.int64)


def cube_with_cells(target_cells: int) -> Tuple[np.ndarray, np.ndarray]:
    """The unit cube with n^3 hexahedra, n chosen so that 6 n^3 is closest to target_cells."""
    if target_cells < 6:
        raise ValueError(f"target_cells must be >= 6, got {target_cells!r}")
    n = max(1, int(round((target_cells / 6.0) ** (1.0 / 3.0))))
    return structured_box(n)
