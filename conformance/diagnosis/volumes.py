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

#: power q of J on the force -> words, the stiffness being the derivative of that force (a
#: difference or complex-step tangent of the engine's own force), not J^q times the oracle's.
DERIVED_FACTORS: Dict[int, str] = {
    1: f"force J times the oracle's, integrated over {_KIRCHHOFF}",
    -1: f"force 1/J times the oracle's, integrated over {_REST}",
    -2: "force 1/J^2 times the oracle's: the deformed volume taken as V / J (the density's "
    "rho = rho0 / J applied to the volume) where v = J V belongs",
    2: "force J^2 times the oracle's: the deformed volume taken as J^2 V, or J applied to the "
    "Kirchhoff stress again and to the volume",
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
    found = _derived_findings(split, J, f, K, s, tol)
    if np.ptp(J) <= _AWAY * np.abs(J).max():
        return ambiguous(found)
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


def _derived_findings(
    split: ElementSplit, J: np.ndarray, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The factors J_c^q of :data:`DERIVED_FACTORS` on the element forces, with the element
    matrices of their derivative, whose assembly matches the engine: on any state, a uniform J
    included (the derivative's term f_e (x) dJ/dx is no constant factor).
    """
    if np.all(np.abs(J - 1.0) < _AWAY):
        return []  # J^q is 1 and its derivative's term vanishes with the rest forces
    found = []
    # The stiffness the derivative of the scaled force: K_e' = J^q K_e - q J^(q-1) f_e (x) dJ/dx
    # (K = -df/dx), dJ/dx_a = J F^-T grad N_a.
    m = split.cells.shape[0]
    dJ = J[:, None, None] * np.einsum("mal,mlk->mak", split.D, np.linalg.inv(split.F))
    for q, words in DERIVED_FACTORS.items():
        fq = split.fe * (J**q)[:, None, None]
        Kq = split.Ke * (J**q)[:, None, None] - q * np.einsum(
            "m,mi,mj->mij", J ** (q - 1), split.fe.reshape(m, 12), dJ.reshape(m, 12)
        )
        fc, Kc = assemble(split.cells, split.n, fq, Kq)
        e = errors(f, sp.csr_matrix(K), None, fc, Kc, 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    "volume-factor",
                    f"{words}; the stiffness the derivative of that force",
                    FULL,
                    f"the oracle's element forces times J_c^{q} and the element matrices of "
                    f"their derivative (J from {J.min():.4g} to {J.max():.4g} over the cells), "
                    f"assembled: force error {e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"force_power": q, "derived": True, "residual": max(e.force, e.stiffness)},
                )
            )
    return found
