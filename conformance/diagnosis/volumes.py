"""Force or stiffness integrated over the wrong volume: a factor J (or 1/J) of each cell.

An updated-Lagrangian engine integrates the Cauchy stress and the spatial tangent over the
deformed volume v = J V; a total-Lagrangian one integrates P and A over the rest volume V. The
volume confused (the rest volume with Cauchy quantities, the deformed one with Kirchhoff ones
tau = J sigma and J c, or one integral over each) multiplies a cell's force and/or stiffness by
J_c^q and J_c^p, q, p in {-1, 0, 1}. On a state where every cell has the same J this looks like a
constant factor; a constant factor that is the state's J (or 1/J) is read here as the volume
(:func:`uniform_volume_words`), the number alone only when it is not J. Where J varies from cell
to cell the factor is tested cell by cell on the oracle's element forces and matrices
(:func:`volume_findings`): a constant factor cannot fit there, J_c^p can.
"""

from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["VOLUME_FACTORS", "uniform_volume_words", "volume_findings"]

_REST = "the rest volume V where the deformed volume v = J V belongs (Cauchy stress / c over V)"
_KIRCHHOFF = (
    "the deformed volume v = J V with quantities that already carry J (the Kirchhoff stress "
    "tau = J sigma, J c), or the factor J applied twice"
)

#: (power of J on the force, on the stiffness) -> words: the engine's cell force is J^q and its
#: cell stiffness J^p times the oracle's.
VOLUME_FACTORS: Dict[Tuple[int, int], str] = {
    (1, 1): f"force and stiffness J times the oracle's: integrated over {_KIRCHHOFF}",
    (-1, -1): f"force and stiffness 1/J times the oracle's: integrated over {_REST}",
    (0, -1): "stiffness integrated over the rest volume V, the force over the deformed volume "
    "v = J V: the stiffness is 1/J times the oracle's (the factor J missing from it)",
    (0, 1): f"stiffness J times the oracle's, the force right: the stiffness integrated over "
    f"{_KIRCHHOFF}",
    (-1, 0): "force integrated over the rest volume V, the stiffness over the deformed volume "
    "v = J V: the force is 1/J times the oracle's (the factor J missing from it)",
    (1, 0): f"force J times the oracle's, the stiffness right: the force integrated over "
    f"{_KIRCHHOFF}",
}

#: The factor equals J^p within this (relative), and J differs from 1 by at least _AWAY.
_SAME = 1e-6
_AWAY = 1e-3


def uniform_volume_words(q: int, p: int, ratio: float, J: np.ndarray) -> Optional[str]:
    """Words for an engine/oracle ``ratio`` fitted on the force (q = 1, p = 0), the stiffness
    (q = 0, p = 1) or both (q = p = 1) when it is the J^(+-1) of a state whose cells (J: (m,))
    all share one J away from 1; None otherwise (the number is then said as a constant factor).
    """
    if J.size == 0 or np.ptp(J) > 1e-9 * np.abs(J).max() or abs(J[0] - 1.0) < _AWAY:
        return None
    for k in (1, -1):
        if abs(ratio - J[0] ** k) <= _SAME * abs(J[0] ** k):
            words = VOLUME_FACTORS[(q * k, p * k)]
            return f"{words} (J = {J[0]:.6g} in every cell of this state, factor {ratio:.6g})"
    return None


def volume_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The factors (J_c^q on the force, J_c^p on the stiffness) of :data:`VOLUME_FACTORS` whose
    assembly of the oracle's element forces (m, 4, 3) and matrices (m, 12, 12) matches the
    engine; only on a state whose cells do not share one J (there a constant factor is said by
    the global-scale reading, :func:`uniform_volume_words`). Several: ambiguous.
    """
    J = np.linalg.det(split.F)
    if np.ptp(J) <= _AWAY * np.abs(J).max():
        return []
    found = []
    for (q, p), words in VOLUME_FACTORS.items():
        fc, Kc = assemble(
            split.cells,
            split.n,
            split.fe * (J**q)[:, None, None],
            split.Ke * (J**p)[:, None, None],
        )
        e = errors(f, sp.csr_matrix(K), None, fc, Kc, 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    "volume-factor",
                    words,
                    FULL,
                    f"the oracle's element forces times J_c^{q} and element matrices times "
                    f"J_c^{p} (MJED's, whose sum is the oracle's to {split.residual:.1e}; J from "
                    f"{J.min():.4g} to {J.max():.4g} over the cells), assembled: force error "
                    f"{e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"force_power": q, "stiffness_power": p, "residual": max(e.force, e.stiffness)},
                )
            )
    return ambiguous(found)
