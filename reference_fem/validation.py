"""Input checks for the oracle: shapes, dtypes, finite values, cell orientation.

Kept free of dolfinx and UFL so that they can be tested and reused without them.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "AsReadFrame",
    "check_points",
    "check_cells",
    "check_positions",
    "check_frame",
    "signed_volumes",
]


def check_points(points) -> np.ndarray:
    """Rest positions as a C-contiguous float64 array of shape (n, 3), finite."""
    X = np.asarray(points, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or X.shape[0] < 4:
        raise ValueError(f"points must have shape (n, 3) with n >= 4, got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"points contain {np.count_nonzero(~np.isfinite(X))} non-finite value(s)")
    return np.ascontiguousarray(X)


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volumes (m,) of the tetrahedra ``cells`` (m, 4) over ``points`` (n, 3)."""
    p = points[cells]  # (m, 4, 3)
    edges = p[:, 1:, :] - p[:, :1, :]  # (m, 3, 3): rows x1-x0, x2-x0, x3-x0
    return np.linalg.det(edges) / 6.0


def check_cells(cells, points: np.ndarray) -> np.ndarray:
    """Cells as an int64 array (m, 4) of valid, distinct node indices, positively oriented.

    Raises:
        ValueError: wrong shape, non-integer or out-of-range indices, repeated nodes in a
            cell, or a cell whose signed volume is not clearly positive.
    """
    raw = np.asarray(cells)
    if raw.ndim != 2 or raw.shape[1] != 4 or raw.shape[0] < 1:
        raise ValueError(f"cells must have shape (m, 4) with m >= 1, got {raw.shape}")
    if not np.issubdtype(raw.dtype, np.integer):
        raise ValueError(f"cells must hold integer node indices, got dtype {raw.dtype}")
    T = np.ascontiguousarray(raw, dtype=np.int64)
    n = points.shape[0]
    if T.min() < 0 or T.max() >= n:
        raise ValueError(
            f"cell node indices must lie in [0, {n}), got range [{T.min()}, {T.max()}]"
        )
    s = np.sort(T, axis=1)
    repeated = np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1))
    if repeated.size:
        c = repeated[0]
        raise ValueError(f"{repeated.size} cell(s) repeat a node, first: cell {c} = {T[c]}")
    vol = signed_volumes(points, T)
    # Relative to the cube of the mean edge length, so the check does not depend on units.
    p = points[T]
    h = np.mean(np.linalg.norm(p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]], axis=2), axis=1)
    bad = np.flatnonzero(vol <= 1e-12 * h**3)
    if bad.size:
        c = bad[0]
        raise ValueError(
            f"{bad.size} cell(s) are not positively oriented or are degenerate (first: cell {c}, "
            f"signed volume {vol[c]:.3g}); swap two nodes of inverted cells"
        )
    return T


def check_positions(x, n: int) -> np.ndarray:
    """Current positions as float64 (n, 3), finite."""
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (n, 3):
        raise ValueError(f"positions must have shape ({n}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(
            f"positions contain {np.count_nonzero(~np.isfinite(a))} non-finite value(s)"
        )
    return a


class AsReadFrame(np.ndarray):
    """Per-cell 3x3 matrices that a mistaken engine read from a kit's frame file in another
    layout, hence not rotations: the diagnosis asks the oracle for the energy with them as
    written (R^T E R and the like stay defined), which :func:`check_frame` otherwise refuses.
    Made with ``array.view(AsReadFrame)``; never from user input.
    """


def check_frame(frame, m: int, *, tol: float = 1e-8) -> np.ndarray:
    """A fibre frame (Costa, a user energy with I4/I5): None, a (3, 3) or (m, 3, 3) orthonormal
    frame; returned as (m, 3, 3).

    Orthonormality (R^T R = I to ``tol``) is required, except of an :class:`AsReadFrame`;
    det R = -1 is allowed, since flipping the sign of a frame column leaves
    Q = sum B_ij Ef_ij^2 unchanged.
    """
    as_read = isinstance(frame, AsReadFrame)
    if frame is None:
        return np.broadcast_to(np.eye(3), (m, 3, 3))
    R = np.asarray(frame, dtype=np.float64)
    if R.shape == (3, 3):
        R = np.broadcast_to(R, (m, 3, 3))
    if R.shape != (m, 3, 3):
        raise ValueError(f"fibre frame must have shape (3, 3) or ({m}, 3, 3), got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError("fibre frame contains non-finite values")
    err = np.abs(np.einsum("cki,ckj->cij", R, R) - np.eye(3)).reshape(m, 9).max(axis=1)
    if np.any(err > tol) and not as_read:
        c = int(np.argmax(err))
        raise ValueError(
            f"fibre frame must be orthonormal (R^T R = I); cell {c}: max |R^T R - I| = {err[c]:.3g}"
        )
    return R
