"""One invariant's gradient wrong in a hand-written first Piola stress, the stiffness derived
apart and right.

An engine written in F (a graphics-style engine: P = dPsi/dF and dP/dF as two formulas) builds
its stress from the invariants' gradients,

    P = sum_a Psi_a dI_a/dF,

in one of two invariant sets: (I1, I2, J) with gradients 2 F, 2 (I1 F - F C), cof F, or
(I_C, II_C, J) = (tr C, tr C^2, J) with 2 F, 4 F C, cof F. A gradient typed with a wrong factor
(dII_C/dF written 2 F C, as if d(C : C) were 2 C : dC with dC = F^T dF) scales one piece of P
and so of the force, while the tangent, a formula of its own, stays right.

Psi_a is the declared energy's derivative in each invariant of the set (complex step in the
invariants its formula reads, and the chain rule to the set), per cell: nothing is read back
from the engine. Each piece's force is assembled, its factor k fitted with one unknown to the
force error (the stiffness must already be the oracle's), and the hypothesis named when the
fitted force is within the case's tolerance and k is a simple number (2, 1/2, 0, -1, ...). A
material without a scalar formula of these invariants (Ogden, Costa) is not read.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    alike_cells,
    assemble,
    cell_kinematics,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.diagnosis.fractions import simple_fraction
from conformance.diagnosis.term_differences import cell_invariants, declared_energy
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "SETS",
    "invariant_slopes",
    "gradient_pieces",
    "gradient_tensors",
    "j_hessian_tensor",
    "gradient_findings",
    "gradient_reading",
]

#: set -> ((invariant name, its gradient in words), ...): the two invariant sets engines use.
SETS: Dict[str, Tuple[Tuple[str, str], ...]] = {
    "I1, I2, J": (("I1", "dI1/dF = 2 F"), ("I2", "dI2/dF = 2 (I1 F - F C)"), ("J", "cof F")),
    "I_C, II_C, J": (("I_C", "dI_C/dF = 2 F"), ("II_C", "dII_C/dF = 4 F C"), ("J", "cof F")),
}


def _chain(inv: Dict[str, np.ndarray], which: str) -> Dict[str, Tuple]:
    """For each scalar the declared energy may read, its derivatives in the invariants of set
    ``which`` (the other two held): {name: (d/da, d/db, d/dJ)}.
    """
    J, I1 = inv["J"], inv["I1"]
    one, zero = np.ones_like(J), np.zeros_like(J)
    j23, j43 = J ** (-2.0 / 3.0), J ** (-4.0 / 3.0)
    if which == "I1, I2, J":
        return {
            "I1": (one, zero, zero),
            "I2": (zero, one, zero),
            "J": (zero, zero, one),
            "I3": (zero, zero, 2.0 * J),
            "I1b": (j23, zero, -2.0 / 3.0 * inv["I1b"] / J),
            "I2b": (zero, j43, -4.0 / 3.0 * inv["I2b"] / J),
        }
    # I2 = (I_C^2 - II_C) / 2
    return {
        "I1": (one, zero, zero),
        "I2": (I1, -0.5 * one, zero),
        "J": (zero, zero, one),
        "I3": (zero, zero, 2.0 * J),
        "I1b": (j23, zero, -2.0 / 3.0 * inv["I1b"] / J),
        "I2b": (j43 * I1, -0.5 * j43, -4.0 / 3.0 * inv["I2b"] / J),
    }


def invariant_slopes(model: Any, F: np.ndarray, which: str) -> Optional[np.ndarray]:
    """(3, m) the declared energy's derivatives Psi_a in the invariants of set ``which`` at
    deformation gradients F (m, 3, 3); None without a scalar formula of the invariants.
    """
    energy = declared_energy(model)
    if energy is None:
        return None
    inv = cell_invariants(F)
    if not set(energy.variables) <= set(inv):
        return None
    chain = _chain(inv, which)
    h = 1e-30  # complex step: exact to round-off
    out = np.zeros((3, F.shape[0]))
    for name in energy.variables:
        shifted = {**inv, name: inv[name] + 1j * h}
        with np.errstate(all="ignore"):
            W = np.asarray(energy.evaluate(shifted.__getitem__, np.log, np.exp, np.sqrt))
        slope = np.imag(W) / h
        out += slope * np.stack(chain[name])
    return out if np.all(np.isfinite(out)) else None


def gradient_tensors(F: np.ndarray, which: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gradients dI_a/dF (each (m, 3, 3)) of the invariants of set ``which``."""
    C = F.swapaxes(1, 2) @ F
    I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
    cof = np.linalg.det(F)[:, None, None] * np.linalg.inv(F).swapaxes(1, 2)
    second = 2.0 * (I1 * F - F @ C) if which == "I1, I2, J" else 4.0 * F @ C
    return 2.0 * F, second, cof


def gradient_pieces(F: np.ndarray, slopes: np.ndarray, which: str) -> List[np.ndarray]:
    """The three pieces Psi_a dI_a/dF (each (m, 3, 3)) of P in set ``which``."""
    return [slopes[a][:, None, None] * g for a, g in enumerate(gradient_tensors(F, which))]


#: The gradients of a cell must be independent to this (smallest over largest singular value
#: of the 9 x 3 matrix of their entries, normalised) to read Psi_a back from P.
_INDEPENDENT = 1e-6


def slopes_from_stress(P: np.ndarray, F: np.ndarray, which: str) -> Optional[np.ndarray]:
    """(3, m) Psi_a read back from each cell's P = sum_a Psi_a dI_a/dF (least squares over
    its nine entries; an isotropic law's P is exactly of that form), or None where some cell's
    gradients are not independent (two equal principal stretches) or P is not of that form.
    """
    grads = np.stack([g.reshape(-1, 9) for g in gradient_tensors(F, which)], axis=2)  # (m, 9, 3)
    G = grads / np.maximum(np.linalg.norm(grads, axis=1, keepdims=True), 1e-300)
    sv = np.linalg.svd(G, compute_uv=False)
    if np.any(sv[:, -1] < _INDEPENDENT * sv[:, 0]):
        return None
    out = np.empty((3, F.shape[0]))
    Pf = P.reshape(-1, 9)
    normal = np.einsum("mia,mib->mab", grads, grads)  # per cell: a 9 x 3 system
    rhs = np.einsum("mia,mi->ma", grads, Pf)
    out[:] = np.linalg.solve(normal, rhs[..., None])[..., 0].T
    left = np.einsum("mia,am->mi", grads, out) - Pf
    if np.linalg.norm(left) > 1e-9 * np.linalg.norm(Pf):
        return None
    return out


def gradient_findings(
    model: Any, points, cells, x, f: np.ndarray, K, f_o: np.ndarray, K_o, s: Scales, tol
) -> List[Finding]:
    """The pieces whose factor, fitted to the force error with the stiffness the oracle's,
    brings the force within ``tol`` with a simple factor (several: ambiguous).
    """
    base = errors(f, K, None, f_o, K_o, 0.0, s)
    if base.force <= tol.force:
        return []
    # the stiffness right: the gradient alone typed wrongly in P; the stiffness wrong too: the
    # slope Psi_a itself, in P and in its term Psi_a d2I_a/dF2 of the tangent
    slope = base.stiffness > tol.stiffness
    V0, D, F = cell_kinematics(points, cells, x)
    n = points.shape[0]
    df = np.ravel(np.asarray(f, dtype=float) - f_o)
    K_o = sp.csr_matrix(K_o)
    DK = sp.csr_matrix(K) - K_o
    m = cells.shape[0]
    found = []
    P = None
    for which, names in SETS.items():
        slopes = invariant_slopes(model, F, which)
        source = f"the declared energy by complex step, the chain rule to {which}"
        if slopes is None:
            source = "read back from the oracle's stress per cell, P = sum_a Psi_a dI_a/dF"
            # no scalar formula of these invariants: read back from the oracle's stress
            if P is None:
                P = _cell_stress(model, points, cells, x, f_o, K_o, s, tol)
            slopes = None if P is None else slopes_from_stress(P, F, which)
        if slopes is None:
            continue
        hessians = _hessians(F, which) if slope else None
        for a, ((name, words), piece) in enumerate(zip(names, gradient_pieces(F, slopes, which))):
            if name == "J" and which != "I1, I2, J":
                continue  # dW/dJ with (I_C, II_C) held is dW/dJ with (I1, I2) held: said once
            g = np.ravel(assemble(cells, n, piola_element_forces(V0, D, piece), None)[0])
            if not g.any():
                continue
            dK = None
            if slope:
                dA = slopes[a][:, None, None, None, None] * hessians[a]
                Ke = tangent_element_matrices(V0, D, dA)
                dK = assemble(cells, n, np.zeros((m, 4, 3)), Ke)[1]
            c = _factor(g, df, dK, DK, s)
            k = simple_fraction(1.0 + c, 4, 1e-6)
            if k is None or k == 1:
                continue
            Kp = K_o if dK is None else K_o + (float(k) - 1.0) * dK
            e = errors(f, K, None, f_o + (float(k) - 1.0) * g.reshape(-1, 3), Kp, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            found.append(_finding(which, name, words, float(k), e, source, slope))
    return ambiguous(found)


def _factor(g: np.ndarray, df: np.ndarray, dK, DK, s: Scales) -> float:
    """The least-squares c with df = c g (and, given dK, DK = c dK), each side over its scale."""
    num = float(g @ df) / s.force**2
    den = float(g @ g) / s.force**2
    if dK is not None:
        num += float(dK.multiply(DK).sum()) / s.stiffness**2
        den += float(dK.multiply(dK).sum()) / s.stiffness**2
    return num / den if den > 0 else 0.0


def _levi_civita() -> np.ndarray:
    e = np.zeros((3, 3, 3))
    e[0, 1, 2] = e[1, 2, 0] = e[2, 0, 1] = 1.0
    e[0, 2, 1] = e[2, 1, 0] = e[1, 0, 2] = -1.0
    return e


def j_hessian_tensor(F: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) d2J / dF_kI dF_lL = eps_klm eps_ILM F_mM: the cross-product matrices of
    F's columns in a block layout.
    """
    e = _levi_civita()
    return np.einsum("klm,ILM,nmM->nkIlL", e, e, F, optimize=True)


def _hessians(F: np.ndarray, which: str) -> List[np.ndarray]:
    """The invariants' second gradients d2I_a / dF_kI dF_lL (each (m, 3, 3, 3, 3)) of set
    ``which``.
    """
    eye = np.eye(3)
    C = F.swapaxes(1, 2) @ F
    B = F @ F.swapaxes(1, 2)
    h_ic = np.broadcast_to(2.0 * np.einsum("kl,IL->kIlL", eye, eye), (F.shape[0],) + (3,) * 4)
    h_iic = 4.0 * (
        np.einsum("kl,mLI->mkIlL", eye, C)
        + np.einsum("mkL,mlI->mkIlL", F, F)
        + np.einsum("mkl,IL->mkIlL", B, eye)
    )
    h_j = j_hessian_tensor(F)
    if which == "I1, I2, J":  # I2 = (I_C^2 - II_C) / 2
        I1 = np.trace(C, axis1=1, axis2=2)[:, None, None, None, None]
        h_i2 = I1 * h_ic + 4.0 * np.einsum("mkI,mlL->mkIlL", F, F) - 0.5 * h_iic
        return [h_ic, h_i2, h_j]
    return [h_ic, h_iic, h_j]


def _cell_stress(model, points, cells, x, f_o, K_o, s, tol) -> Optional[np.ndarray]:
    """(m, 3, 3) the oracle's first Piola stress per cell (MJED's split, used only where it adds
    up to the oracle's), or None.
    """
    from conformance.diagnosis.elements import cell_piola, element_split

    split = element_split(model, points, cells, x, f_o, K_o, s, tol)
    return None if split is None else cell_piola(split)[0]


def _finding(which: str, name: str, words: str, k: float, e, source: str, slope: bool):
    said = {2.0: "doubled", 0.5: "halved", 0.0: "left out", -1.0: "with its sign flipped"}
    how = said.get(k, f"times {k:g}")
    if slope:
        title = (
            f"the derivative dW/d{name} {how} where it multiplies {name}'s gradient and second "
            f"gradient (the invariants {which}): in P and in the term dW/d{name} d2{name}/dF2 "
            "of the tangent, the second derivatives of W right (a chain-rule factor of "
            f"d{name}, e.g. the sign of dI2b/dII_C, typed wrongly)"
        )
        after = f"and its second gradient term; force error {e.force:.1e}, stiffness error"
    else:
        title = (
            f"your first Piola stress has the piece dW/d{name} {words} {how} (the invariants "
            f"{which}), the stiffness derived apart and right: a gradient typed wrongly in P"
        )
        after = f"force error {e.force:.1e}; the stiffness is the oracle's"
    return Finding(
        "invariant-gradient-piece" if not slope else "invariant-slope-piece",
        title,
        FULL,
        f"the energy's derivative in {name} per cell ({source}) times that gradient, scaled "
        f"by {k:g} and assembled, {after} ({e.stiffness:.1e})",
        {
            "set": which,
            "invariant": name,
            "factor": k,
            "slope": slope,
            "residual": max(e.force, e.stiffness),
        },
    )


def gradient_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force wrong, the stiffness right, nothing named) led by
    :func:`gradient_findings` when one fits; unchanged otherwise.
    """
    from dataclasses import replace

    tol: Tolerances = diag.tolerances
    found = gradient_findings(
        ci.model, ci.points, ci.cells, ci.positions, out.force, out.stiffness, ref.force,
        ref.stiffness, s, tol,
    )  # fmt: skip
    if found:
        return named_first(diag, found)
    if not _fits_alike_cells(ci.points, ci.cells, ci.positions, out, ref, s, tol):
        return diag
    # One state in every cell: the pieces' factors cannot be told apart here; a case of the kit
    # where the cells differ names the piece (corroborate.fits_codes).
    head = diag.findings[0] if diag.findings else None
    if head is None or head.code != "unexplained":
        return diag
    codes = [*head.figures.get("fits_codes", ()), "invariant-gradient-piece"]
    figures = {**head.figures, "fits_codes": codes}
    return replace(diag, findings=[replace(head, figures=figures), *diag.findings[1:]])


def _fits_alike_cells(points, cells, x, out, ref, s: Scales, tol: Tolerances) -> bool:
    """True on a state whose cells share one F where the stiffness is right and the force
    error is a combination of the invariants' gradients' forces (three numbers for the mesh):
    a piece of P scaled fits it, whichever piece.
    """
    V0, D, F = cell_kinematics(points, cells, x)
    if not alike_cells(F):
        return False
    n = points.shape[0]
    cols = [
        np.ravel(assemble(cells, n, piola_element_forces(V0, D, g), None)[0])
        for g in gradient_tensors(F, "I_C, II_C, J")
    ]
    A = np.stack(cols, axis=1)
    df = np.ravel(np.asarray(out.force, dtype=float) - ref.force)
    beta, *_ = np.linalg.lstsq(A, df, rcond=None)
    fitted = ref.force + (A @ beta).reshape(-1, 3)
    e = errors(out.force, out.stiffness, None, fitted, ref.stiffness, 0.0, s)
    return e.force <= tol.force and e.stiffness <= tol.stiffness
