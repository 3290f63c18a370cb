"""A material tangent applied to each direction by differences of the stress along it.

An engine whose material routine answers "the elasticity tensor applied to a symmetric strain
direction H" (SOFA's ``applyElasticity``-style interfaces: dS = CC : H) may compute it as a
difference of the stress along that very direction,

    dS(H) ~ (S(E + h H) - S(E)) / h        (C + 2 h H in place of E + h H),

for each node dof's direction H_bl = sym(F^T e_l D_b^T) of each cell. Its leading error,
(h/2) dCC[H][H], is quadratic in H: not a fixed change of the tangent (which the Voigt-column
differences of :mod:`conformance.diagnosis.strain_differences` fit), but one per direction.
It is built here from the oracle's tangent differentiated in the strain (``strain_derivatives``:
dD_AB/d(eps_C) per cell), assembled per cell as V0 (F dS_err(H_bl) D_a)_k in row (a, k), column
(b, l), and the step fitted with one unknown. An edge-based engine computes one block of each
node pair and writes the other as its transpose, so the error is assembled three ways (every
block; the blocks above the local diagonal mirrored; those below mirrored) and the best fit
kept. Named, partly explaining (round-off and the higher orders are left), when it accounts for
99 % of the stiffness error, as the other difference readings are.
"""

from __future__ import annotations

from typing import List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.strain_differences import (
    EXPLAINED,
    VOIGT,
    StrainDifferenceFit,
    fit_step,
    strain_derivatives,
)

__all__ = ["ASSEMBLIES", "direction_errors", "directional_basis", "directional_findings"]

#: How the engine fills a cell's 4 x 4 node blocks from the blocks it computes: name -> words.
ASSEMBLIES = {
    "every": "every node block computed",
    "upper": "the blocks of local pairs a < b computed, those of b > a written as their transposes",
    "lower": "the blocks of local pairs a > b computed, those of a < b written as their transposes",
}


def _voigt_of(H: np.ndarray) -> np.ndarray:
    """(..., 6) the Voigt vector of symmetric strains H (..., 3, 3), engineering shear."""
    return np.stack([(1.0 if i == j else 2.0) * H[..., i, j] for i, j in VOIGT], axis=-1)


def _tensor_of(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the symmetric stress whose Voigt vector (no factor on shear) is v (..., 6)."""
    T = np.zeros(v.shape[:-1] + (3, 3))
    for A, (i, j) in enumerate(VOIGT):
        T[..., i, j] = v[..., A]
        T[..., j, i] = v[..., A]
    return T


def direction_errors(split: ElementSplit, dD: np.ndarray) -> np.ndarray:
    """(m, 4, 3, 3, 3): the leading error per unit step, (1/2) dCC[H][H], of the stress change
    along each node dof's direction H_bl = sym(F^T e_l D_b^T), indexed [cell, b, l, i, j];
    dD: (m, 6, 6, 6) dD_AB/d(eps_C).
    """
    F, D = split.F, split.D
    # dF = e_l D_b^T, F^T dF = F[l, :]^T D_b (rows of F as the column of F^T): (m, 4, 3, 3, 3)
    FtdF = np.einsum("mli,mbj->mblij", F, D)
    H = 0.5 * (FtdF + np.swapaxes(FtdF, -1, -2))
    h = _voigt_of(H)  # (m, 4, 3, 6)
    err = 0.5 * np.einsum("mABC,mblB,mblC->mblA", dD, h, h)
    return _tensor_of(err)


def directional_basis(split: ElementSplit, dS: np.ndarray, assembly: str) -> sp.csr_matrix:
    """The assembled stiffness change V0 (F dS[b, l] D_a)_k (rows (a, k), columns (b, l)) of
    per-direction stress changes dS (m, 4, 3, 3, 3), filled as ``assembly`` says.
    """
    Ke = np.einsum("m,mkI,mblIJ,maJ->makbl", split.V0, split.F, dS, split.D)  # (m,4,3,4,3)
    if assembly != "every":
        a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
        written = a > b if assembly == "upper" else a < b  # the transposed ones
        mirrored = Ke.transpose(0, 3, 4, 1, 2)  # [m, a, k, b, l] = Ke[m, b, l, a, k]
        Ke = np.where(written[None, :, None, :, None], mirrored, Ke)
    m = split.V0.size
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


def directional_findings(
    model, split: ElementSplit, points: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> List[Tuple[str, StrainDifferenceFit]]:
    """(assembly, fit) of the directional forward (or backward) differences that account for
    :data:`EXPLAINED` of D = K - K_o, best first; empty when none does.
    """
    dD = strain_derivatives(model, split, points)
    if dD is None or not np.all(np.isfinite(dD)):
        return []
    dS = direction_errors(split, dD)
    out = []
    for assembly in ASSEMBLIES:
        fit: Optional[StrainDifferenceFit] = fit_step(
            directional_basis(split, dS, assembly), D, K_o, "directional"
        )
        if fit is not None and fit.explained >= EXPLAINED:
            out.append((assembly, fit))
    return sorted(out, key=lambda af: -af[1].explained)
