"""Element matrices made positive semi-definite before assembly.

Real-time engines whose Newton or implicit-Euler solver needs a definite matrix often project
each cell's 12 x 12 stiffness onto the positive semi-definite cone: eigen-decompose it, clamp
its negative eigenvalues to zero (or take their absolute values), rebuild it. That is a solver
safeguard, not the Hessian: wherever a cell's true Hessian is indefinite (a compressed direction
of St Venant-Kirchhoff, a state past a limit point, a large initial stress) the assembled
stiffness differs, and wherever it is definite it does not (a uniaxial stretch may show nothing).

The prediction is exact, nothing fitted: the oracle's element matrices (MJED's split, used only
where their sum is the oracle's) projected in each way and assembled, compared with the engine's
stiffness within the case's tolerance, the force right. A projection that changes nothing on
this state (every cell definite) is not named: it is not told from the Hessian here.
"""

from __future__ import annotations

from typing import Callable, Dict, List

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["PROJECTIONS", "projected", "definiteness_findings"]


def _clamped(w: np.ndarray) -> np.ndarray:
    return np.maximum(w, 0.0)


def _absolute(w: np.ndarray) -> np.ndarray:
    return np.abs(w)


#: name -> (what the engine does to each eigenvalue of a cell's matrix, in words)
PROJECTIONS: Dict[str, tuple] = {
    "clamped": (_clamped, "negative eigenvalues clamped to zero"),
    "absolute": (_absolute, "negative eigenvalues replaced by their absolute values"),
}


def projected(Ke: np.ndarray, change: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(m, 12, 12) each symmetric element matrix of Ke rebuilt from its eigenvectors with its
    eigenvalues passed through ``change`` (the matrix symmetrised first, as eigh reads it).
    """
    w, V = np.linalg.eigh(0.5 * (Ke + np.swapaxes(Ke, 1, 2)))
    return np.einsum("mij,mj,mkj->mik", V, change(w), V, optimize=True)


def definiteness_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The projections of :data:`PROJECTIONS` whose assembly of the oracle's projected element
    matrices matches the engine (force right, stiffness within the tolerance), where the
    projection changes the oracle's stiffness beyond the tolerance; several: ambiguous.
    """
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    base = errors(f, K, None, f0, K0, 0.0, s)
    if base.force > tol.force or base.stiffness <= tol.stiffness:
        return []
    w = np.linalg.eigvalsh(0.5 * (split.Ke + np.swapaxes(split.Ke, 1, 2)))
    scale = np.abs(w).max(axis=1, keepdims=True)
    indefinite = int(np.sum(np.any(w < -1e-8 * scale, axis=1)))
    found = []
    for name, (change, words) in PROJECTIONS.items():
        Kp = assemble(split.cells, split.n, split.fe, projected(split.Ke, change))[1]
        if errors(f0, Kp, None, f0, K0, 0.0, s).stiffness <= tol.stiffness:
            continue  # no cell changed here: not told from the Hessian
        e = errors(f, K, None, f0, Kp, 0.0, s)
        if e.stiffness > tol.stiffness:
            continue
        found.append(
            Finding(
                "element-stiffness-projected",
                "each element stiffness made positive semi-definite before assembly (its "
                f"{words}): a solver's safeguard, not the Hessian of the energy",
                FULL,
                f"the oracle's 12 x 12 element matrices (MJED's split; {indefinite} of "
                f"{split.V0.size} cells indefinite at this state) eigen-decomposed, {words}, "
                f"rebuilt and assembled give your stiffness: error {e.stiffness:.1e} (against "
                f"{base.stiffness:.1e} unprojected); the force matches",
                {"projection": name, "indefinite_cells": indefinite, "residual": e.stiffness},
            )
        )
    return ambiguous(found)
