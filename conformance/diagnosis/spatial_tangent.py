"""A spatial (updated-Lagrangian) tangent pushed forward without its 1/J.

An engine that writes the Cauchy stress and the spatial tangent c = (F F F F : CC) / J and
integrates over the current volume v = J V0 gets the material stiffness V0 B^T CC B exactly;
without the 1/J of c (the Kirchhoff tangent) it gets J times it, cell by cell, while the force
and the geometric stiffness stay right. On a state with one J the symptom is "material
stiffness scaled by J": :func:`spatial_factor_words` says which J; on a state where J varies,
:func:`spatial_findings` tests the factor J_c (and 1/J_c) per cell on the oracle's per-cell
material stiffness.

The push-forward itself, sigma = F S F^T / J and c = F F F F : CC / J with the spatial shape
gradients grad N_a = F^-T D_a and the current volume v = J V0, is :func:`spatial_cells`: the
readings of updated-Lagrangian mistakes (:mod:`conformance.diagnosis.spatial_variants`,
:mod:`conformance.diagnosis.spatial_assembly`) start from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding

__all__ = [
    "SpatialCells",
    "spatial_cells",
    "FACTORS",
    "spatial_factor_words",
    "material_stiffness",
    "spatial_findings",
]


@dataclass(frozen=True)
class SpatialCells:
    """Per cell (m cells): sigma (m, 3, 3) the Cauchy stress, c (m, 3, 3, 3, 3) the spatial
    tangent c[i, j, k, l], gN (m, 4, 3) the spatial shape gradients grad N_a = F^-T D_a (rows,
    the row form D F^-1), v (m,) current volumes J V0.
    """

    sigma: np.ndarray
    c: np.ndarray
    gN: np.ndarray
    v: np.ndarray


def spatial_cells(split: ElementSplit, S: np.ndarray, CC: np.ndarray) -> SpatialCells:
    """The spatial quantities of the split's cells from the second Piola stress S (m, 3, 3) and
    the material tangent CC = dS/dE (m, 3, 3, 3, 3): the push-forward by F with its 1/J.
    """
    F = split.F
    J = np.linalg.det(F)
    sigma = F @ S @ F.swapaxes(1, 2) / J[:, None, None]
    c = np.einsum("miI,mjJ,mkK,mlL,mIJKL->mijkl", F, F, F, F, CC, optimize=True)
    gN = split.D @ np.linalg.inv(F)  # rows grad N_a = F^-T D_a
    return SpatialCells(sigma, c / J[:, None, None, None, None], gN, J * split.V0)


#: power of J -> the mistake it names (the engine's material stiffness is J^p times the oracle's).
FACTORS = {
    1: "1/J missing in the spatial (Kirchhoff) tangent: c = F F F F : CC written without its "
    "1/J and integrated over the current volume, so the material stiffness is J times the "
    "oracle's",
    -1: "1/J applied twice to the spatial tangent (or the rest volume used with c = "
    "F F F F : CC / J): the material stiffness is 1/J times the oracle's",
}

#: The factor equals J^p within this (relative).
SAME = 1e-6


def spatial_factor_words(ratio: float, J: np.ndarray) -> Optional[str]:
    """The mistake of :data:`FACTORS` whose factor J^p equals ``ratio`` (the engine's material
    stiffness over the oracle's) on a state with a single J (J: (m,) per cell); else None.
    """
    if J.size == 0 or np.ptp(J) > 1e-9 * np.abs(J).max() or abs(J[0] - 1.0) < 1e-3:
        return None
    for p, words in FACTORS.items():
        if abs(ratio - J[0] ** p) <= SAME * abs(J[0] ** p):
            return f"{words} (J = {J[0]:.6g} in this state)"
    return None


def material_stiffness(split: ElementSplit, S: np.ndarray) -> np.ndarray:
    """(m, 12, 12) the split's element matrices less their geometric part V0 D_a S D_b I."""
    geo = np.einsum("maI,mIL,mbL,kl->makbl", split.D, S, split.D, np.eye(3))
    return split.Ke - (split.V0[:, None, None, None, None] * geo).reshape(-1, 12, 12)


def spatial_findings(
    split: ElementSplit,
    S: np.ndarray,
    J: np.ndarray,
    matches: Callable[[np.ndarray, sp.csr_matrix], float],
) -> List[Finding]:
    """The factors J_c^p of the material stiffness the engine matches (its force unchanged);
    only on a state whose cells do not all share one J (the other is said by the tangent-part
    fit's words). S: (m, 3, 3) per-cell stress; J: (m,).
    """
    if np.ptp(J) <= 1e-9 * np.abs(J).max():
        return []
    Km = material_stiffness(split, S)
    found = []
    for p, words in FACTORS.items():
        Ke = split.Ke + (J**p - 1.0)[:, None, None] * Km
        f, K = assemble(split.cells, split.n, split.fe, Ke)
        left = matches(f, K)
        if np.isfinite(left):
            found.append(
                Finding(
                    "spatial-tangent-j",
                    words,
                    FULL,
                    "the oracle's material stiffness per cell (element matrices less the "
                    f"geometric part) times J_c^{p} (J from {J.min():.4g} to {J.max():.4g}), "
                    f"the force and geometric stiffness kept: errors against your engine "
                    f"{left:.1e}",
                    {"power": p, "residual": left},
                )
            )
    return found
