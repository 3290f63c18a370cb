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
kept. Central differences, (S(E + h H) - S(E - h H)) / (2 h), err by h^2 times the third
derivative: that error is measured per unit h^2 by simulating the scheme with a larger step
(:data:`CENTRAL_PROBE`, the stress from MJED at each moved C) against the exact change from the
oracle's tangent, and h^2 fitted. Named, partly explaining (round-off and the higher orders are
left), when it accounts for 99 % of the stiffness error, as the other difference readings are.
"""

from __future__ import annotations

from typing import List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola, mirrored_pairs
from conformance.diagnosis.strain_differences import (
    EXPLAINED,
    VOIGT,
    StrainDifferenceFit,
    fit_step,
    fit_step_squared,
    strain_derivatives,
)

__all__ = [
    "ASSEMBLIES",
    "direction_errors",
    "directional_basis",
    "directional_findings",
    "directional_difference_reading",
]

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
    h = _voigt_of(_directions(split))  # (m, 4, 3, 6)
    err = 0.5 * np.einsum("mABC,mblB,mblC->mblA", dD, h, h)
    return _tensor_of(err)


def directional_basis(split: ElementSplit, dS: np.ndarray, assembly: str) -> sp.csr_matrix:
    """The assembled stiffness change V0 (F dS[b, l] D_a)_k (rows (a, k), columns (b, l)) of
    per-direction stress changes dS (m, 4, 3, 3, 3), filled as ``assembly`` says.
    """
    m = split.V0.size
    Ke = np.einsum("m,mkI,mblIJ,maJ->makbl", split.V0, split.F, dS, split.D).reshape(m, 12, 12)
    if assembly != "every":
        Ke = mirrored_pairs(Ke, assembly)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke)[1]


#: The step in E of the simulated central differences that give the central scheme's leading
#: error per unit h^2 (its O(h^4) rest is 1e-6 of it; its round-off u |S| / h, 1e-13 of S).
CENTRAL_PROBE = 1e-3


def _directions(split: ElementSplit) -> np.ndarray:
    """(m, 4, 3, 3, 3): H_bl = sym(F^T e_l D_b^T) per cell, node b and component l."""
    FtdF = np.einsum("mli,mbj->mblij", split.F, split.D)
    return 0.5 * (FtdF + np.swapaxes(FtdF, -1, -2))


def _second_piola(model, points: np.ndarray, split: ElementSplit, C: np.ndarray):
    """(m, 3, 3) the material's S at right Cauchy-Green tensors C (m, 3, 3) through F = sqrt(C)
    (MJED on the cells exploded); None where it cannot.
    """
    from conformance.diagnosis.routine_inputs import piola_at

    w, V = np.linalg.eigh(C)
    if np.any(w <= 0.0):
        return None
    U = np.einsum("mij,mj,mkj->mik", V, np.sqrt(w), V)
    at = piola_at(model, points, split, U, stiffness=False)
    return None if at is None else np.linalg.solve(U, at[0])


def central_errors(model, split: ElementSplit, points: np.ndarray) -> Optional[np.ndarray]:
    """(m, 4, 3, 3, 3): the central scheme's error per unit h^2 in the stress change along
    each H_bl, (S(C + 2 h H) - S(C - 2 h H)) / (2 h) - dS(H) at h = :data:`CENTRAL_PROBE`,
    divided by h^2; dS(H) exact from the oracle's tangent (F^-1 (A[dF] - dF S)). None where the
    material cannot be evaluated.
    """
    P, A = cell_piola(split)
    F, D = split.F, split.D
    Fi = np.linalg.inv(F)
    S = Fi @ P
    H = _directions(split)
    h = CENTRAL_PROBE
    C = np.swapaxes(F, 1, 2) @ F
    out = np.empty_like(H)
    for b in range(4):
        for ll in range(3):
            plus = _second_piola(model, points, split, C + 2 * h * H[:, b, ll])
            minus = _second_piola(model, points, split, C - 2 * h * H[:, b, ll])
            if plus is None or minus is None:
                return None
            dF = np.zeros_like(F)
            dF[:, ll, :] = D[:, b, :]
            exact = Fi @ (np.einsum("mkilj,mlj->mki", A, dF) - dF @ S)
            out[:, b, ll] = ((plus - minus) / (2 * h) - exact) / h**2
    return out


def directional_findings(
    model, split: ElementSplit, points: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> List[Tuple[str, StrainDifferenceFit]]:
    """(assembly, fit) of the directional forward (or backward) differences that account for
    :data:`EXPLAINED` of D = K - K_o, best first; empty when none does.
    """
    out = []
    dD = strain_derivatives(model, split, points)
    if dD is not None and np.all(np.isfinite(dD)):
        dS = direction_errors(split, dD)
        for assembly in ASSEMBLIES:
            fit: Optional[StrainDifferenceFit] = fit_step(
                directional_basis(split, dS, assembly), D, K_o, "directional"
            )
            if fit is not None and fit.explained >= EXPLAINED:
                out.append((assembly, fit))
    if not out:  # central differences: the error quadratic in the step
        dS = central_errors(model, split, points)
        if dS is not None and np.all(np.isfinite(dS)):
            for assembly in ASSEMBLIES:
                basis = directional_basis(split, dS, assembly)
                central = fit_step_squared(basis, D, K_o, "directional")
                if central is not None:
                    out.append((assembly, central))
    return sorted(out, key=lambda af: -af[1].explained)


def directional_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force right, nothing named: after the Voigt-column, perturbation and
    first-elasticity schemes of :mod:`conformance.diagnosis.strain_differences`) with the
    directional differences named first, partly explaining, when a scheme accounts for
    :data:`EXPLAINED` of the stiffness error; unchanged otherwise.
    """
    from conformance.diagnosis.elements import case_split
    from conformance.diagnosis.findings import PARTIAL, Finding, named_first

    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    K_o = sp.csr_matrix(ref.stiffness)
    D = (sp.csr_matrix(out.stiffness) - K_o).tocsr()
    with np.errstate(all="ignore"):
        found = directional_findings(ci.model, split, ci.points, D, K_o)
    if not found:
        return diag
    assembly, fit = found[0]
    lead = (
        "h^2 times the error per unit h^2, measured by simulating the scheme with h = "
        f"{CENTRAL_PROBE:g} against the oracle's exact change"
        if fit.scheme == "central"
        else "(h/2) dCC[H][H], from the oracle's tangent differentiated in the strain"
    )
    return named_first(
        diag,
        [
            Finding(
                "directional-finite-difference",
                f"a finite-difference material tangent: {fit.words()}",
                PARTIAL,
                f"K - K_oracle is the leading error of that scheme in the stress change along "
                f"each node dof's strain direction H ({lead}), {ASSEMBLIES[assembly]}, fitted "
                f"with one unknown: it accounts for {100 * fit.explained:.2f} % of the "
                f"stiffness error (left: {fit.residual:.1e}, the higher orders and round-off); "
                "the force matches",
                {
                    "step": fit.step,
                    "scheme": fit.scheme,
                    "explained": fit.explained,
                    "assembly": assembly,
                },
            )
        ],
    )
