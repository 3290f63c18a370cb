"""The tolerances of "agrees with the oracle", and the length scale they are measured against.

Both applications judge with these figures: the studies (``comparisons``) when MJED is held to
the UFL oracle, and the checker (``conformance``) when another engine is. Keeping them here,
below both, means a verdict can never be stricter in one place than in the other by accident.

Errors are relative, in double precision:

    force_rel_err     = ||f - f_oracle||_2 / ||f_oracle||_2
    stiffness_rel_err = ||K - K_oracle||_F / ||K_oracle||_F
    symmetry_err      = ||K - K^T||_F / ||K||_F
"""

from __future__ import annotations

import numpy as np

__all__ = ["FORCE_TOL", "STIFFNESS_TOL", "SYMMETRY_TOL", "mean_edge_length"]

#: Two double-precision discretisations of one energy agree to round-off times the
#: conditioning of a few thousand cells; 1e-10 leaves three decades of margin over what the
#: equivalence study measures on the paper's meshes, and is far below any modelling mistake.
FORCE_TOL = 1e-10
STIFFNESS_TOL = 1e-10
#: A stiffness assembled from symmetric element blocks is symmetric up to summation order.
SYMMETRY_TOL = 1e-12


def mean_edge_length(points: np.ndarray, cells: np.ndarray) -> float:
    """Mean length of the six edges of every cell [length unit of ``points``].

    points (n, 3), cells (m, 4). The length scale of a mesh, for relative perturbations and
    force scales.
    """
    i, j = np.triu_indices(4, k=1)
    X = points[cells]
    return float(np.linalg.norm(X[:, i] - X[:, j], axis=2).mean())
