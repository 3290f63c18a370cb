"""The deformation gradient formed from the edge matrices wrongly, then used consistently.

Engines in the total-Lagrangian and graphics traditions form F per cell from edge matrices:
the rest edges Dm = [X1 - X0, X2 - X0, X3 - X0] and the deformed ones Ds likewise, as columns,
F = Ds Dm^-1. Stacking the edges as rows on one side, or multiplying in the other order, gives
another 3 x 3 matrix F' that depends on the cell's rest shape, not on F alone (Ds^T Dm^-1 =
Dm^T F^T Dm^-1), so no energy variant in F describes it. An engine that then builds its stress,
its strain-displacement matrices and its tangent from F' with the right shape-function
gradients computes, per cell, exactly what a correct engine computes for that cell deformed by
F'. So each variant F' predicts the engine's force and stiffness: MJED's element arrays of the
cells, each on its own nodes, placed at x'_a = F' X_a, assembled. A variant is named when that
prediction matches the engine within the tolerances (nothing fitted). NumPy and MJED only.
"""

from __future__ import annotations

from typing import Any, Dict, List

import numpy as np

from conformance.diagnosis.elements import assemble, mjed_element_arrays
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.judge.compare import Scales, Tolerances, errors, grown

__all__ = ["edge_variants", "edge_kinematics_findings", "edge_kinematics_reading"]


def edge_variants(X: np.ndarray, x: np.ndarray) -> Dict[str, np.ndarray]:
    """{words: F' (m, 3, 3)} for rest and deformed node coordinates X, x (m, 4, 3)."""
    Dm = (X[:, 1:] - X[:, :1]).swapaxes(1, 2)  # edges as columns
    Ds = (x[:, 1:] - x[:, :1]).swapaxes(1, 2)
    Dmi = np.linalg.inv(Dm)
    return {
        "the deformed edge matrix Ds built with the edges as rows while Dm has them as "
        "columns: F = Ds^T Dm^-1 where Ds Dm^-1 belongs": Ds.swapaxes(1, 2) @ Dmi,
        "the rest edge matrix Dm built with the edges as rows while Ds has them as columns: "
        "F = Ds Dm^-T where Ds Dm^-1 belongs": Ds @ Dmi.swapaxes(1, 2),
        "the product in the other order: F = Dm^-1 Ds where Ds Dm^-1 belongs": Dmi @ Ds,
        "both edge matrices built with the edges as rows: F = Ds^T Dm^-T where Ds Dm^-1 "
        "belongs": Ds.swapaxes(1, 2) @ Dmi.swapaxes(1, 2),
    }


def edge_kinematics_findings(
    model: Any, points: np.ndarray, cells: np.ndarray, positions: np.ndarray, out,
    s: Scales, tol: Tolerances,
) -> List[Finding]:  # fmt: skip
    """The findings naming an edge-matrix variant of :func:`edge_variants` whose element arrays
    match the engine's force and stiffness (several distinct: ambiguous).
    """
    m = cells.shape[0]
    X, x = points[cells], positions[cells]
    own = np.arange(4 * m, dtype=np.int64).reshape(m, 4)
    found = []
    for words, Fp in edge_variants(X, x).items():
        if np.any(np.linalg.det(Fp) <= 0.0):
            continue  # inverted: MJED has no element arrays there
        xp = np.einsum("mij,maj->mai", Fp, X)
        arrays = mjed_element_arrays(model, X.reshape(-1, 3), own, xp.reshape(-1, 3))
        if arrays is None or not all(np.all(np.isfinite(a)) for a in arrays):
            continue
        f, K = assemble(cells, points.shape[0], *arrays)
        # matched to the variant's own round-off where it is far larger than the oracle
        e = errors(out.force, out.stiffness, None, f, K, 0.0, grown(s, f, K))
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    "edge-kinematics",
                    f"the deformation gradient formed from the edge matrices wrongly: {words} "
                    "(then used consistently: stress, strain-displacement matrices and tangent "
                    "from it)",
                    FULL,
                    "MJED's element arrays of every cell deformed by that F' on its own nodes, "
                    f"assembled, give your force to {e.force:.1e} and your stiffness to "
                    f"{e.stiffness:.1e}, nothing fitted",
                    {"variant": words},
                )
            )
    return ambiguous(found) if len(found) > 1 else found


def edge_kinematics_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet, the force wrong) with an edge-matrix
    variant of F named first; unchanged when none matches.
    """
    if diag.errors.force <= diag.tolerances.force:
        return diag
    with np.errstate(all="ignore"):
        found = edge_kinematics_findings(
            ci.model, ci.points, ci.cells, ci.positions, out, s, diag.tolerances
        )
    return named_first(diag, found)
