"""Badly shaped meshes, the kind users' meshes contain: slivers, caps, wedges, needles, graded
cells over many orders of magnitude of volume, and meshes in any length unit.

Quality is the normalised mean-ratio measure 6 sqrt(2) V / l_rms^3 (1 for the regular
tetrahedron, 0 for a flat one; l_rms is the root mean square of the six edge lengths).

All functions are pure and seeded: the same arguments give the same mesh.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

from meshes.tetra import signed_volumes

__all__ = ["quality", "heights", "DEGENERACIES", "degrade", "graded", "stretched"]

Mesh = Tuple[np.ndarray, np.ndarray]

_EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])

#: How one vertex of a cell is moved to make it bad (the other three stay)::
#:
#:     cap    toward the centroid of the opposite face (the vertex nearly on the face's inside);
#:     sliver toward the midpoint of an edge of the opposite face (four nearly coplanar vertices
#:            with two nearly crossing edges);
#:     wedge  toward another vertex of the cell (one short edge).
DEGENERACIES = ("cap", "sliver", "wedge")


def quality(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(m,) normalised quality 6 sqrt(2) V / l_rms^3 of every cell (signed: < 0 when inverted).

    points (n, 3), cells (m, 4); dimensionless, independent of the length unit.
    """
    x = np.asarray(points, dtype=np.float64)[np.asarray(cells)]
    l2 = np.sum((x[:, _EDGES[:, 0]] - x[:, _EDGES[:, 1]]) ** 2, axis=2).mean(axis=1)
    return 6.0 * np.sqrt(2.0) * signed_volumes(points, cells) / l2**1.5


def heights(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(m,) smallest height of every cell: 3 |V| / (largest face area) [length unit of points]."""
    x = np.asarray(points, dtype=np.float64)[np.asarray(cells)]
    faces = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))
    areas = np.stack(
        [
            0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1)
            for a, b, c in faces
        ],
        axis=1,
    )
    return 3.0 * np.abs(signed_volumes(points, cells)) / areas.max(axis=1)


def _target(
    points: np.ndarray, cell: np.ndarray, a: int, kind: str, rng: np.random.Generator
) -> np.ndarray:
    others = [b for b in range(4) if b != a]
    face = points[cell[others]]
    if kind == "cap":
        return face.mean(axis=0)
    if kind == "sliver":
        i, j = rng.choice(3, size=2, replace=False)
        return 0.5 * (face[i] + face[j])
    if kind == "wedge":
        return face[rng.integers(3)]
    raise ValueError(f"unknown degeneracy {kind!r}; known: {', '.join(DEGENERACIES)}")


def degrade(
    points: np.ndarray,
    cells: np.ndarray,
    kind: str,
    min_quality: float,
    *,
    seed: int = 0,
    tries: int = 200,
) -> np.ndarray:
    """Move one node so that one cell becomes a ``kind`` of quality at most ``min_quality``,
    every cell staying positively oriented.

    Args:
        points: (n, 3) positively oriented mesh's nodes; cells: (m, 4).
        kind: one of DEGENERACIES; min_quality: in (0, 1), e.g. 1e-3.
        seed: which cell, vertex and target are tried first.

    Returns:
        (n, 3) new points (cells unchanged).

    Raises:
        ValueError: no node of the tried cells can be moved that far without inverting a cell.
    """
    if not 0.0 < min_quality < 1.0:
        raise ValueError(f"min_quality must lie in (0, 1), got {min_quality}")
    if kind not in DEGENERACIES:
        raise ValueError(f"unknown degeneracy {kind!r}; known: {', '.join(DEGENERACIES)}")
    rng = np.random.default_rng(seed)
    P = np.asarray(points, dtype=np.float64)
    C = np.asarray(cells)
    for _ in range(tries):
        c = int(rng.integers(len(C)))
        a = int(rng.integers(4))
        node = C[c, a]
        start, goal = P[node].copy(), _target(P, C[c], a, kind, rng)
        touching = np.flatnonzero(np.any(C == node, axis=1))  # only these cells change
        # Bisection on the fraction t of the way to the goal: the cell's quality falls with t.
        lo, hi = 0.0, 1.0
        Q = P.copy()
        for _ in range(60):
            t = 0.5 * (lo + hi)
            Q[node] = start + t * (goal - start)
            q = quality(Q, C[touching])
            if q.min() <= 0.0:
                hi = t
            elif q.min() > min_quality:
                lo = t
            else:
                return Q
        # the goal itself is reached without inverting but not bad enough: try another cell
    raise ValueError(
        f"no {kind} of quality <= {min_quality:g} found in {tries} tries (seed {seed})"
    )


def graded(points: np.ndarray, power: float) -> np.ndarray:
    """Nodes mapped by X_i -> lo_i + L_i ((X_i - lo_i) / L_i)^power per axis (a monotone grading
    toward the lower corner): cell volumes then span about power x 3 x log10(1/h) orders of
    magnitude for a mesh of spacing h. points (n, 3); power >= 1.
    """
    if power < 1.0:
        raise ValueError(f"power must be >= 1, got {power}")
    P = np.asarray(points, dtype=np.float64)
    lo, L = P.min(axis=0), np.ptp(P, axis=0)
    return lo + L * ((P - lo) / L) ** power


def stretched(points: np.ndarray, factors) -> np.ndarray:
    """Nodes scaled per axis by ``factors`` (3,): an anisotropic mesh of needles and flat cells."""
    return np.asarray(points, dtype=np.float64) * np.asarray(factors, dtype=np.float64)
