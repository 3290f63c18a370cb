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
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

__all__ = [
    "FORCE_TOL",
    "STIFFNESS_TOL",
    "SYMMETRY_TOL",
    "compare_arrays",
    "mean_edge_length",
]

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


def compare_arrays(f_m, K_m, f_o, K_o, force_scale: float) -> tuple:
    """(force_rel_err, stiffness_rel_err, symmetry_err) of MJED (f_m, K_m) against the oracle."""
    K_m = sp.csr_matrix(K_m)
    K_o = sp.csr_matrix(K_o)
    nK = sparse_norm(K_o)
    f_ref = max(float(np.linalg.norm(f_o)), force_scale * nK)
    df = float(np.linalg.norm(np.asarray(f_m) - np.asarray(f_o)))
    force_err = df / f_ref if f_ref > 0 else df
    stiff_err = float(sparse_norm(K_m - K_o)) / nK if nK > 0 else float(sparse_norm(K_m))
    nKm = sparse_norm(K_m)
    sym_err = float(sparse_norm(K_m - K_m.T)) / nKm if nKm > 0 else 0.0
    return force_err, stiff_err, sym_err
