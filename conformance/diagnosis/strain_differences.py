"""A material tangent D = dS/dE built by differences of the stress in the strain components.

An engine that computes the Voigt tangent column by column, D e_B = (S(E + h e_B) - S(E)) / h
with e_B a unit step of the B-th Voigt strain component (engineering shear: a shear column
moves E_kl = E_lk by h / 2), has the error (h / 2) dD_AB / d(eps_B) + O(h^2) in its column B,
cell by cell. Differencing the force by the nodes (:mod:`conformance.diagnosis.tangent`,
:mod:`conformance.diagnosis.differences`) leaves another error, so this one is tested on its
own: dD/d(eps_B) per cell by central differences of the oracle's tangent (MJED's element
matrices on the mesh with its cells pulled apart, each cell's F moved so that its E moves by
+-delta e_B), the stiffness of (1/2) dD_AB / d(eps_B) assembled, and the step fitted with one
unknown. Named when it accounts for nearly all of the stiffness error (99 %), as the other
difference readings are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola
from conformance.diagnosis.invariant_pieces import cell_tensors

__all__ = [
    "VOIGT",
    "unit_strain",
    "voigt_vector",
    "symmetric_from_voigt",
    "voigt_matrix",
    "voigt_tensor",
    "material_stiffness",
    "strain_derivatives",
    "StrainDifferenceFit",
    "fit_step_squared",
    "fit_strain_differences",
    "strain_difference_reading",
]

#: Voigt order 11, 22, 33, 12, 23, 13 as (i, j) pairs.
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
#: Central-difference step in the strain (dimensionless).
DELTA = 1e-4
#: Fraction of the stiffness error a fit must account for to be named.
EXPLAINED = 0.99
#: ...or this much, where what is left is at most ROUNDOFF_FACTOR times the round-off that the
#: fitted step's quotient makes (a step so small that cancellation is a visible part).
NOISY_EXPLAINED = 0.9
ROUNDOFF_FACTOR = 3.0


def piola_roundoff(split: ElementSplit, step: float) -> float:
    """The expected Frobenius norm of the assembled round-off of a first elasticity tensor by
    one-sided differences of P with step ``step``: each entry of A off by about sqrt(2) u |P| /
    h (two stresses rounded, u = 2^-53, |P| the cell's largest entry), independently, so that
    E ||K||^2 = sum over cells of 9 V0^2 sigma^2 (sum_a |D_a|^2)^2.
    """
    P, _ = cell_piola(split)
    sigma = np.sqrt(2.0) * 2.0**-53 * np.abs(P).reshape(P.shape[0], -1).max(axis=1) / step
    spread = np.sum(split.D**2, axis=(1, 2))
    return float(np.sqrt(np.sum(9.0 * split.V0**2 * sigma**2 * spread**2)))


def unit_strain(B: int) -> np.ndarray:
    """(3, 3) the strain of a unit step of Voigt component B (engineering shear: E_kl = 1/2)."""
    i, j = VOIGT[B]
    e = np.zeros((3, 3))
    e[i, j] += 0.5
    e[j, i] += 0.5
    return e


def strain_derivatives(model: Any, split: ElementSplit, points: np.ndarray) -> Optional[np.ndarray]:
    """(m, 6, 6, 6) dD_AB / d(eps_C) per cell (D the Voigt material tangent, eps the Voigt
    strain with engineering shear), or None when MJED cannot evaluate the model there.
    """
    import mjed

    cells, F = split.cells, split.F
    m = cells.shape[0]
    X = points[cells]  # (m, 4, 3)
    loose = np.arange(4 * m).reshape(m, 4)
    Xc = X - X[:, :1]
    Ci = np.linalg.inv(F.swapaxes(1, 2) @ F)
    out = np.empty((m, 6, 6, 6))
    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), loose), model)
        for c in range(6):
            tangents = []
            for sign in (1.0, -1.0):
                # F (I + delta C^-1 e): C moves by 2 delta e to first order, the second order
                # even in delta, so the central difference is exact to O(delta^2).
                Fs = F @ (np.eye(3) + sign * DELTA * Ci @ unit_strain(c))
                xs = (np.einsum("mij,maj->mai", Fs, Xc) + X[:, :1]).reshape(-1, 3)
                fe = np.asarray(field.element_forces(xs), dtype=np.float64)
                Ke = np.asarray(field.element_stiffness(xs), dtype=np.float64)
                moved = ElementSplit(loose, 4 * m, split.V0, split.D, Fs, fe, Ke, 0.0)
                t = cell_tensors(*cell_piola(moved), Fs)
                tangents.append(voigt_matrix(t.CC))
            out[:, :, :, c] = (tangents[0] - tangents[1]) / (2.0 * DELTA)
    except Exception:  # noqa: BLE001 - not an MJED material, or an inverted moved cell
        return None
    return out


def voigt_vector(S: np.ndarray) -> np.ndarray:
    """(m, 6) the Voigt components (order :data:`VOIGT`) of symmetric tensors S (m, 3, 3)."""
    return np.stack([S[:, i, j] for i, j in VOIGT], axis=1)


def symmetric_from_voigt(v: np.ndarray) -> np.ndarray:
    """(m, 3, 3) the symmetric tensors whose Voigt components (order :data:`VOIGT`) are v (m, 6)."""
    T = np.zeros((v.shape[0], 3, 3), dtype=v.dtype)
    for a, (i, j) in enumerate(VOIGT):
        T[:, i, j] = T[:, j, i] = v[:, a]
    return T


def voigt_matrix(CC: np.ndarray) -> np.ndarray:
    """(m, 6, 6) the Voigt matrix of a minor-symmetric tangent (m, 3, 3, 3, 3)."""
    i = np.array([p[0] for p in VOIGT])
    j = np.array([p[1] for p in VOIGT])
    return CC[:, i[:, None], j[:, None], i[None, :], j[None, :]]


def voigt_tensor(Dv: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the minor-symmetric tensor whose Voigt matrix is Dv (m, 6, 6)."""
    T = np.zeros((Dv.shape[0], 3, 3, 3, 3))
    for A, (i, j) in enumerate(VOIGT):
        for B, (k, ll) in enumerate(VOIGT):
            for p, q in {(i, j), (j, i)}:
                for r, s in {(k, ll), (ll, k)}:
                    T[:, p, q, r, s] = Dv[:, A, B]
    return T


def material_stiffness(split: ElementSplit, dCC: np.ndarray) -> sp.csr_matrix:
    """The assembled V0 D_a F dCC F D_b of per-cell tangent changes dCC (m, 3, 3, 3, 3)."""
    mat = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", split.D, split.F, dCC, split.F, split.D)
    Ke = (split.V0[:, None, None, None, None] * mat).reshape(-1, 12, 12)
    return assemble(split.cells, split.n, np.zeros((split.V0.size, 4, 3)), Ke)[1]


@dataclass(frozen=True)
class StrainDifferenceFit:
    """scheme ("forward" / "backward"); step: h; explained: the fraction of ||K - K_o||
    accounted for; residual: what is left, relative to ||K_o||; kind: "strain" (differences of
    S in the strain), "perturbation" (Miehe's perturbation of F,
    :mod:`conformance.diagnosis.perturbation_differences`) or "first-elasticity" (differences
    of P in each component of F).
    """

    scheme: str
    step: float
    explained: float
    residual: float
    kind: str = "strain"

    def words(self) -> str:
        if self.kind == "directional":
            quotient = (
                "(S(E + h H) - S(E - h H)) / (2 h)"
                if self.scheme == "central"
                else "(S(E + h H) - S(E)) / h"
            )
            return (
                f"{self.scheme} differences of the stress S along each node's strain direction "
                f"H (the elasticity tensor applied to H as {quotient}, C moved by 2 h H), "
                f"step h = {self.step:.2e} in E"
            )
        if self.kind == "first-elasticity":
            return (
                f"{self.scheme} differences of the first Piola stress P in each component of F "
                f"(the first elasticity tensor A = dP/dF numerically), step h = {self.step:.2e}"
            )
        if self.kind == "perturbation":
            return (
                f"{self.scheme} differences of the Kirchhoff stress under Miehe's perturbation "
                f"of F (F + eps sym(e_k e_l) F, a numerical spatial tangent), step eps = "
                f"{self.step:.2e}"
            )
        return (
            f"{self.scheme} differences of the stress S in each Voigt strain component of E "
            f"(engineering shear strains), step h = {self.step:.2e}"
        )


def fit_step(
    Bm: sp.csr_matrix, D: sp.csr_matrix, K_o: sp.csr_matrix, kind: str = "strain"
) -> Optional[StrainDifferenceFit]:
    """The step that best explains D = K - K_o (3n, 3n) as ``step`` x Bm (the stiffness of a
    scheme's leading error per unit step), one unknown; None when D or Bm is zero.
    """
    nD = float(sparse_norm(D))
    bb = float(Bm.multiply(Bm).sum())
    if nD == 0.0 or bb == 0.0:
        return None
    c = float(Bm.multiply(D).sum()) / bb
    left = float(sparse_norm(D - c * Bm))
    return StrainDifferenceFit(
        "forward" if c > 0 else "backward",
        abs(c),
        1.0 - left / nD,
        left / float(sparse_norm(K_o)),
        kind,
    )


def fit_step_squared(
    Bm: sp.csr_matrix, D: sp.csr_matrix, K_o: sp.csr_matrix, kind: str
) -> Optional[StrainDifferenceFit]:
    """A central scheme's step h from D = K - K_o as h^2 x Bm (Bm the stiffness of its error per
    unit h^2), one unknown; None when D or Bm is zero, the fitted h^2 is not positive, or the
    fit accounts for less than :data:`EXPLAINED` of D.
    """
    fit = fit_step(Bm, D, K_o, kind)
    if fit is None or fit.scheme != "forward" or fit.explained < EXPLAINED:
        return None
    return StrainDifferenceFit(
        "central", float(np.sqrt(fit.step)), fit.explained, fit.residual, kind
    )


def fit_strain_differences(
    split: ElementSplit, dD: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> Optional[StrainDifferenceFit]:
    """The step that best explains D = K - K_o (3n, 3n) as the leading error of forward
    (backward: a negative step) differences in the strain components, with one unknown;
    dD: (m, 6, 6, 6) from :func:`strain_derivatives`. None when D or the basis is zero.
    """
    lead = 0.5 * np.einsum("mABB->mAB", dD)  # column B's error per unit step
    return fit_step(material_stiffness(split, voigt_tensor(lead)), D, K_o)


#: kind -> (code, what the leading error is, in words)
_EVIDENCE = {
    "strain": (
        "strain-finite-difference",
        "(h/2) dD_AB/d(eps_B) in column B of the Voigt tangent, from the oracle's tangent "
        "differentiated in the strain",
    ),
    "perturbation": (
        "perturbation-finite-difference",
        "(eps/2) tau''_kl / J in column kl of the spatial tangent, tau'' the oracle's Kirchhoff "
        "stress differentiated twice along the perturbation",
    ),
    "first-elasticity": (
        "first-elasticity-finite-difference",
        "(h/2) d2P_kI/dF_lL^2 in column lL of A = dP/dF, from the oracle's first Piola stress "
        "differentiated twice in that component of F",
    ),
}

#: kind -> the tangent it is, in words
_TANGENT = {
    "strain": "material",
    "perturbation": "spatial",
    "first-elasticity": "first elasticity",
}


def strain_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force right, nothing named) with a finite-difference tangent named first
    (partly explaining: the higher orders and round-off are left) when a scheme's fit (in the
    strain, Miehe's perturbation of F, or P differenced in F's components) accounts for
    :data:`EXPLAINED` of the stiffness error; several: said as ambiguous; when none does, a
    perturbation of F of another form
    (:func:`conformance.diagnosis.perturbation_differences.scheme_findings`); unchanged when
    none fits.
    """
    from dataclasses import replace

    from conformance.diagnosis.elements import case_split
    from conformance.diagnosis.findings import PARTIAL, Finding, ambiguous
    from conformance.diagnosis.perturbation_differences import (
        kirchhoff_curvatures,
        perturbation_basis,
        piola_basis,
        scheme_findings,
    )

    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    K_o = sp.csr_matrix(ref.stiffness)
    D = (sp.csr_matrix(out.stiffness) - K_o).tocsr()
    fits = []
    with np.errstate(all="ignore"):
        dD = strain_derivatives(ci.model, split, ci.points)
        if dD is not None and np.all(np.isfinite(dD)):
            fits.append(fit_strain_differences(split, dD, D, K_o))
        curv = kirchhoff_curvatures(ci.model, split, ci.points)
        if curv is not None and np.all(np.isfinite(curv)):
            fits.append(fit_step(perturbation_basis(split, curv), D, K_o, "perturbation"))
        Bp = piola_basis(ci.model, split, ci.points)
        if Bp is not None:
            fits.append(fit_step(Bp, D, K_o, "first-elasticity"))
    found = []
    for fit in fits:
        if fit is None:
            continue
        noise = None
        if fit.explained < EXPLAINED:
            # a small step: the rest may be the quotient's own round-off, predicted from the
            # stresses differenced (P in F's components only: its size is known per cell)
            if fit.kind != "first-elasticity" or fit.explained < NOISY_EXPLAINED:
                continue
            noise = piola_roundoff(split, fit.step) / float(sparse_norm(K_o))
            if fit.residual > ROUNDOFF_FACTOR * noise:
                continue
        code, lead = _EVIDENCE[fit.kind]
        left = (
            "the higher orders and round-off"
            if noise is None
            else f"the round-off of P differenced with that step, predicted at {noise:.1e}"
        )
        found.append(
            Finding(
                code,
                f"a finite-difference {_TANGENT[fit.kind]} tangent: {fit.words()}",
                PARTIAL,
                f"K - K_oracle is the leading error of that scheme per cell ({lead}), fitted "
                f"with one unknown: it accounts for {100 * fit.explained:.2f} % of the "
                f"stiffness error (left: {fit.residual:.1e}, {left}); the force matches",
                {"step": fit.step, "scheme": fit.scheme, "explained": fit.explained},
            )
        )
    why = "the schemes' errors fit alike"
    if not found:  # the perturbation itself wrong?
        with np.errstate(all="ignore"):
            found = scheme_findings(
                ci.model, split, ci.points, D, s.stiffness, diag.tolerances.stiffness
            )
        why = "their perturbations predict the same tangent here"
    if not found:
        return diag
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*ambiguous(found, why), *rest])
