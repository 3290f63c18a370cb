"""A hand-derived stress or tangent with one piece of its chain rule wrong.

Engines written in the total-Lagrangian form compute, per cell, S = 2 dW/dC and
CC = 4 d2W/dCdC by the chain rule through the invariants (I1, I2, J):

    S  = 2 sum_a psi_a g_a,
    CC = 4 sum_ab psi_ab g_a (x) g_b + 4 sum_a psi_a h_a,

with g = (I, I1 I - C, J/2 C^-1) the gradients dI_a/dC and h = (0, I (x) I - II,
J/4 C^-1 (x) C^-1 - J/2 C^-1 (.) C^-1) their second gradients; isochoric laws
W = Psi(I1b, I2b) + U(J) bring their derivatives to (I1, I2, J) through the chain of
I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2. A mistake in one piece (a sign, a term dropped, C for
C^-1) changes S and CC by a combination of the pieces that is fixed once the derivatives psi
are known.

The derivatives are not taken from a material's code: per cell, the oracle's S and CC (read
back from the element matrices, :mod:`conformance.diagnosis.elements`, whose sum is the
oracle's) are fitted on the pieces by linear least squares, with psi_a and psi_ab (nine
unknowns) or, for a law of the isochoric form, the derivatives of Psi and U (seven unknowns).
The fit must reproduce S and CC to round-off (else the law is not of that form and nothing is
claimed). Each mistaken piece then predicts the engine's force and stiffness with no unknown
left; it is named when the prediction matches the engine within the case's tolerance, and only
where the fit determines it (a state whose C has equal eigenvalues leaves some psi free: a
prediction that changes along those freedoms is not made).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding

__all__ = [
    "CellTensors",
    "cell_tensors",
    "LAW_MISTAKES",
    "CHAIN_MISTAKES",
    "J_MISTAKES",
    "PieceFit",
    "j_pieces",
    "stress_tangent",
    "design_columns",
    "fit_columns",
    "determined_change",
    "fit_pieces",
    "derivative_basis",
    "predict",
    "piece_findings",
    "law_fit",
    "SCALED_PIECES",
    "SCALED_FACTORS",
    "scaled_predictions",
    "scaled_words",
]

EYE = np.eye(3)
#: II_IJKL = (d_IK d_JL + d_IL d_JK) / 2, the symmetric fourth-order identity.
II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))
#: A fit of S and CC within this (relative, per cell) holds the law's form.
FIT_TOL = 1e-8
#: Singular values below this fraction of the largest (unit columns) leave an unknown free.
FREE = 1e-9
#: A prediction moving by more than this along a free direction (unit columns) is not made.
DETERMINED = 1e-7


@dataclass(frozen=True)
class CellTensors:
    """Per cell (m cells): F (m, 3, 3), S (m, 3, 3), CC (m, 3, 3, 3, 3) the oracle's second
    Piola-Kirchhoff stress and material tangent dS/dE, with C, its inverse Ci, I1, I2, J (m,).
    """

    F: np.ndarray
    S: np.ndarray
    CC: np.ndarray
    C: np.ndarray
    Ci: np.ndarray
    I1: np.ndarray
    I2: np.ndarray
    J: np.ndarray


def cell_tensors(P: np.ndarray, A: np.ndarray, F: np.ndarray) -> CellTensors:
    """S = F^-1 P and CC from A = dP/dF (A[k, I, l, L] = dP_kI / dF_lL), using
    A_kIlL = d_kl S_LI + F_kJ CC_JIML F_lM; CC minor- and major-symmetrised (round-off only).
    """
    Fi = np.linalg.inv(F)
    S = Fi @ P
    S = 0.5 * (S + S.swapaxes(1, 2))
    T = A - np.einsum("kl,mLI->mkIlL", EYE, S)
    CC = np.einsum("mJk,mkIlL,mMl->mJIML", Fi, T, Fi)
    CC = 0.5 * (CC + CC.swapaxes(1, 2))
    CC = 0.5 * (CC + CC.swapaxes(3, 4))
    CC = 0.5 * (CC + CC.transpose(0, 3, 4, 1, 2))
    C = F.swapaxes(1, 2) @ F
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    return CellTensors(F, S, CC, C, np.linalg.inv(C), I1, I2, np.linalg.det(F))


def _outer(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def _odot(A):
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, A) + np.einsum("mil,mjk->mijkl", A, A))


def _law(t: CellTensors, mistake: str = "") -> Tuple[List[np.ndarray], List[np.ndarray]]:
    """The gradients g_a (m, 3, 3) and second gradients h_a (m, 3, 3, 3, 3) of (I1, I2, J) by
    C, with one of :data:`LAW_MISTAKES` made ("" : none).
    """
    m = t.J.size
    eye = np.broadcast_to(EYE, (m, 3, 3))
    J = t.J[:, None, None]
    J4 = t.J[:, None, None, None, None]
    g = [eye, t.I1[:, None, None] * eye - t.C, 0.5 * J * t.Ci]
    outer_ci, odot_ci = 0.25 * J4 * _outer(t.Ci, t.Ci), 0.5 * J4 * _odot(t.Ci)
    h = [np.zeros((m, 3, 3, 3, 3)), _outer(eye, eye) - II, outer_ci - odot_ci]
    if mistake == "dJ-with-C":
        g[2] = 0.5 * J * t.C
    elif mistake == "dJ-without-J":
        g[2] = 0.5 * t.Ci
    elif mistake == "dI2-sign":
        g[1] = t.I1[:, None, None] * eye + t.C
    elif mistake == "d2I2-no-identity":
        h[1] = _outer(eye, eye)
    elif mistake == "d2I2-identity-sign":
        h[1] = _outer(eye, eye) + II
    elif mistake == "d2I2-missing":
        h[1] = np.zeros_like(h[1])
    elif mistake == "d2J-odot-sign":
        h[2] = outer_ci + odot_ci
    elif mistake == "d2J-odot-missing":
        h[2] = outer_ci
    elif mistake == "d2J-outer-missing":
        h[2] = -odot_ci
    elif mistake == "d2J-missing":
        h[2] = np.zeros_like(h[2])
    return g, h


def j_pieces(t: CellTensors, mistake: str = "") -> Tuple[np.ndarray, np.ndarray]:
    """dJ/dC = J/2 C^-1 (m, 3, 3) and d2J/dCdC = J/4 C^-1 (x) C^-1 - J/2 C^-1 (.) C^-1
    (m, 3, 3, 3, 3): the pieces of J in any law's chain rule, with one of
    :data:`J_MISTAKES` made ("": none).
    """
    g, h = _law(t, mistake)
    return g[2], h[2]


#: code -> title: one piece of (g, h) written wrongly, in the stress and the tangent alike.
LAW_MISTAKES: Dict[str, str] = {
    "dJ-with-C": "dJ/dC written with C for C^-1 (J/2 C instead of J/2 C^-1) in your stress and "
    "tangent",
    "dJ-without-J": "dJ/dC written C^-1/2 (the derivative of ln J) instead of J/2 C^-1 (dJ/dF "
    "= J F^-T without its factor J) in your stress and in the chain-rule products of your "
    "tangent (d2J/dC2 right): every term through J off where J != 1",
    "dI2-sign": "dI2/dC written I1 I + C instead of I1 I - C (the sign of its C term) in your "
    "stress and tangent",
    "d2I2-no-identity": "the -II term of d2I2/dC2 is missing from your tangent (d2I2/dCdC "
    "written I (x) I instead of I (x) I - II)",
    "d2I2-identity-sign": "d2I2/dC2 written I (x) I + II instead of I (x) I - II (pushed "
    "forward: b (x) b + b (.) b for b (x) b - b (.) b), the sign of its symmetric-identity term "
    "flipped in your tangent",
    "d2I2-missing": "the psi_2 d2I2/dC2 term (I (x) I - II) is missing from your tangent",
    "d2J-odot-sign": "d(C^-1)/dC with its sign lost in d2J/dC2: your tangent has "
    "+ J/2 C^-1 (.) C^-1 where d2J/dCdC = J/4 C^-1 (x) C^-1 - J/2 C^-1 (.) C^-1",
    "d2J-odot-missing": "the -J/2 C^-1 (.) C^-1 term of d2J/dC2 is missing from your tangent",
    "d2J-outer-missing": "the J/4 C^-1 (x) C^-1 term of d2J/dC2 is missing from your tangent",
    "d2J-missing": "the psi_J d2J/dC2 term is missing from your tangent",
}

#: The codes of :data:`LAW_MISTAKES` that change J's pieces (dJ/dC, d2J/dCdC) alone: they
#: apply to any law of J and other variables.
J_MISTAKES: Tuple[str, ...] = tuple(c for c in LAW_MISTAKES if c.startswith(("dJ", "d2J")))

#: code -> title: the chain from Psi(I1b, I2b) + U(J) to (I1, I2, J) with one piece wrong.
CHAIN_MISTAKES: Dict[str, str] = {
    "i1b-curvature": "Psi_1 d2I1b/dC2 dropped from your tangent: the second derivatives of "
    "I1b = J^(-2/3) I1 by I1 and J left out of the isochoric chain rule",
    "i1b-projection": "no deviatoric projection of I1b's derivative: J^(-2/3) treated as a "
    "constant when differentiating I1b = J^(-2/3) I1 (isochoric stress 2 J^(-2/3) Psi_1 I, its "
    "-I1/3 C^-1 part missing, in the stress and the tangent)",
    "i2b-curvature": "Psi_2 d2I2b/dC2 dropped from your tangent: the second derivatives of "
    "I2b = J^(-4/3) I2 by I2 and J left out of the isochoric chain rule",
    "i2b-projection": "no deviatoric projection of I2b's derivative: J^(-4/3) treated as a "
    "constant when differentiating I2b = J^(-4/3) I2 (in the stress and the tangent)",
}


def _psi_basis(m: int) -> Tuple[np.ndarray, np.ndarray]:
    """Unknowns psi_1, psi_2, psi_J, psi_11, psi_12, psi_1J, psi_22, psi_2J, psi_JJ as unit
    (dW (9, m, 3), d2W (9, m, 3, 3)) over (I1, I2, J).
    """
    dW = np.zeros((9, m, 3))
    d2W = np.zeros((9, m, 3, 3))
    for a in range(3):
        dW[a, :, a] = 1.0
    for k, (a, b) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), start=3):
        d2W[k, :, a, b] = d2W[k, :, b, a] = 1.0
    return dW, d2W


def _chain_basis(t: CellTensors, mistake: str = "") -> Tuple[np.ndarray, np.ndarray]:
    """Unknowns Psi_1, Psi_2, U', Psi_11, Psi_12, Psi_22, U'' of W = Psi(I1b, I2b) + U(J) as
    (dW (7, m, 3), d2W (7, m, 3, 3)) over (I1, I2, J), with one of :data:`CHAIN_MISTAKES`.
    """
    J, m = t.J, t.J.size
    a, b = J ** (-2.0 / 3.0), J ** (-4.0 / 3.0)
    zero = np.zeros(m)
    g1 = np.stack([a, zero, -2.0 / 3.0 * a * t.I1 / J], axis=1)
    g2 = np.stack([zero, b, -4.0 / 3.0 * b * t.I2 / J], axis=1)
    h1 = np.zeros((m, 3, 3))
    h1[:, 0, 2] = h1[:, 2, 0] = -2.0 / 3.0 * a / J
    h1[:, 2, 2] = 10.0 / 9.0 * a * t.I1 / J**2
    h2 = np.zeros((m, 3, 3))
    h2[:, 1, 2] = h2[:, 2, 1] = -4.0 / 3.0 * b / J
    h2[:, 2, 2] = 28.0 / 9.0 * b * t.I2 / J**2
    if mistake.endswith("projection"):  # J^(-2/3) (or ^(-4/3)) a constant: no J-derivatives
        (g1 if mistake.startswith("i1b") else g2)[:, 2] = 0.0
    if mistake:
        (h1 if mistake.startswith("i1b") else h2)[:] = 0.0
    eJ = np.zeros((m, 3))
    eJ[:, 2] = 1.0
    dW = np.zeros((7, m, 3))
    d2W = np.zeros((7, m, 3, 3))
    dW[0], dW[1], dW[2] = g1, g2, eJ
    d2W[0], d2W[1] = h1, h2
    d2W[3] = np.einsum("ma,mb->mab", g1, g1)
    d2W[4] = np.einsum("ma,mb->mab", g1, g2) + np.einsum("ma,mb->mab", g2, g1)
    d2W[5] = np.einsum("ma,mb->mab", g2, g2)
    d2W[6] = np.einsum("ma,mb->mab", eJ, eJ)
    return dW, d2W


def stress_tangent(
    g, h, dW, d2W, stress: float = 1.0, hessian: float = 1.0, gradient: float = 1.0
) -> Tuple[np.ndarray, np.ndarray]:
    """S (k, m, 3, 3) and CC (k, m, 3, 3, 3, 3) of k unknowns given as dW (k, m, 3) and
    d2W (k, m, 3, 3) over (I1, I2, J), through the pieces g, h (lists of three); stress,
    hessian, gradient: factors on S, on CC's part 4 d2W g (x) g and on its part 4 dW h (1: the
    chain rule as it is).
    """
    G = np.stack(g, axis=1)  # (m, 3, 3, 3)
    H = np.stack(h, axis=1)  # (m, 3, 3, 3, 3, 3)
    S = 2.0 * stress * np.einsum("kma,maij->kmij", dW, G)
    CC = 4.0 * (
        hessian * np.einsum("kmab,maij,mbpq->kmijpq", d2W, G, G)
        + gradient * np.einsum("kma,maijpq->kmijpq", dW, H)
    )
    return S, CC


#: The two forms of law: name -> the unknowns' (dW, d2W) from the cell tensors and a chain
#: mistake ("" for none; the nine psi of W(I1, I2, J) take none).
FORMS: Dict[str, Callable[[CellTensors, str], Tuple[np.ndarray, np.ndarray]]] = {
    "isochoric": _chain_basis,
    "invariants": lambda t, mistake="": _psi_basis(t.J.size),
}


@dataclass(frozen=True)
class PieceFit:
    """The law's derivatives fitted per cell: form (a key of :data:`FORMS`), x (m, k) the
    unknowns, scale (m, k) the columns' norms, free (m, k, k) the unit free directions (rows;
    zero where an unknown is determined), residual the largest relative misfit of (S, CC).
    """

    form: str
    x: np.ndarray
    scale: np.ndarray
    free: np.ndarray
    residual: float
    used: np.ndarray


def design_columns(S: np.ndarray, CC: np.ndarray) -> np.ndarray:
    """(m, 90, k) design columns from S (k, m, 3, 3) and CC (k, m, 3, 3, 3, 3)."""
    k, m = S.shape[:2]
    return np.concatenate([S.reshape(k, m, 9), CC.reshape(k, m, 81)], axis=2).transpose(1, 2, 0)


def _basis(t: CellTensors, form: str, chain: str, used: Optional[np.ndarray]):
    dW, d2W = FORMS[form](t, chain)
    return (dW, d2W) if used is None else (dW[used], d2W[used])


def derivative_basis(t: CellTensors, fit: PieceFit) -> Tuple[np.ndarray, np.ndarray]:
    """(dW (k, m, 3), d2W (k, m, 3, 3)) the derivatives of W by (I1, I2, J) per unit of each
    of ``fit``'s k unknowns: dW/dI_a = sum_k fit.x[:, k] dW[k, :, a], and so d2W.
    """
    return _basis(t, fit.form, "", fit.used)


def fit_pieces(t: CellTensors, form: str, used: Optional[np.ndarray] = None) -> PieceFit:
    """Least squares per cell of the oracle's (S, CC) on the unknowns of ``form`` (only those
    ``used``: (k,) booleans; all by default), through the correct pieces; batched SVD on unit
    columns.
    """
    g, h = _law(t)
    dW, d2W = _basis(t, form, "", used)
    M = design_columns(*stress_tangent(g, h, dW, d2W))
    x, scale, free, residual = fit_columns(M, t.S, t.CC)
    used = np.ones(dW.shape[0], dtype=bool) if used is None else used
    return PieceFit(form, x, scale, free, residual, used)


def fit_columns(
    M: np.ndarray, S: np.ndarray, CC: np.ndarray
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Least squares per cell of (S (m, 3, 3), CC (m, 3, 3, 3, 3)) on the design columns
    M (m, 90, k) (:func:`design_columns`), by a batched SVD on unit columns: (x (m, k) the
    unknowns, scale (m, k) the columns' norms, free (m, k, k) the unit free directions (rows;
    zero where an unknown is determined), the largest relative misfit).
    """
    y = np.concatenate([S.reshape(-1, 9), CC.reshape(-1, 81)], axis=1)
    scale = np.linalg.norm(M, axis=1)
    scale[scale == 0] = 1.0
    U, sv, Vt = np.linalg.svd(M / scale[:, None, :], full_matrices=False)
    keep = sv > FREE * sv[:, :1]
    coef = np.einsum("mik,mi->mk", U, y) / np.where(keep, sv, 1.0) * keep
    xs = np.einsum("mkj,mk->mj", Vt, coef)
    x = xs / scale
    left = np.linalg.norm(np.einsum("mij,mj->mi", M, x) - y, axis=1)
    size = np.maximum(np.linalg.norm(y, axis=1), 1e-300)
    free = Vt * (~keep)[:, :, None]
    return x, scale, free, float(np.max(left / size))


def determined_change(
    L: np.ndarray, x: np.ndarray, scale: np.ndarray, free: np.ndarray
) -> Optional[np.ndarray]:
    """(m, 90) the change L x of (S, CC) that a mistake's design columns L (m, 90, k) (its
    columns less the right ones) make with the fitted unknowns x (m, k); None where it moves
    along a free direction of the fit (:func:`fit_columns`), i.e. is not determined.
    """
    Ls = L / scale[:, None, :]
    moved = np.linalg.norm(np.einsum("mik,mjk->mij", Ls, free), axis=1)  # (m, k)
    size = np.linalg.norm(Ls, axis=(1, 2))
    if np.any(moved.max(axis=1) > DETERMINED * np.maximum(size, 1e-300)):
        return None
    return np.einsum("mik,mk->mi", L, x)


def vanishing(fit: PieceFit, t: CellTensors) -> np.ndarray:
    """(k,) booleans: the unknowns of ``fit`` whose part of (S, CC) is zero in every cell
    (below 1e-10 of the cell's (S, CC)): a law without that derivative, when ``fit`` is made
    at a generic state (C's eigenvalues distinct, every unknown determined).
    """
    y = np.concatenate([t.S.reshape(-1, 9), t.CC.reshape(-1, 81)], axis=1)
    part = np.abs(fit.x) * fit.scale / np.maximum(np.linalg.norm(y, axis=1), 1e-300)[:, None]
    return np.all(part <= 1e-10, axis=0)


def predict(
    t: CellTensors, fit: PieceFit, law: str = "", chain: str = ""
) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """(dS (m, 3, 3), dCC (m, 3, 3, 3, 3)): the engine's minus the oracle's stress and tangent
    with the law mistake ``law`` or the chain mistake ``chain``; None where the fit leaves the
    prediction free (it changes along a free direction).
    """
    right = stress_tangent(*_law(t), *_basis(t, fit.form, "", fit.used))
    wrong = stress_tangent(*_law(t, law), *_basis(t, fit.form, chain, fit.used))
    L = design_columns(wrong[0] - right[0], wrong[1] - right[1])  # (m, 90, k)
    d = determined_change(L, fit.x, fit.scale, fit.free)
    if d is None:
        return None
    m = t.J.size
    return d[:, :9].reshape(m, 3, 3), d[:, 9:].reshape(m, 3, 3, 3, 3)


#: A chain-rule piece scaled: name -> its words; "dI{a}" (a gradient g_a wherever it enters,
#: the stress and the tangent's products), "d2I{a}" (a second gradient h_a), "hessian" (the
#: part 4 sum_ab W_ab g_a (x) g_b), "gradient" (the part 4 sum_a W_a h_a), "stress" (S alone).
SCALED_PIECES: Dict[str, str] = {
    "dI0": "dI1/dC = I",
    "dI1": "dI2/dC = I1 I - C",
    "dI2": "dJ/dC = J/2 C^-1",
    "d2I1": "d2I2/dC2 = I (x) I - II (its term 4 W_2 d2I2/dC2)",
    "d2I2": "d2J/dC2 = J/4 C^-1 (x) C^-1 - J/2 C^-1 (.) C^-1 (its term 4 W_J d2J/dC2)",
    "hessian": "the Hessian part 4 sum_ab d2W/dI_a dI_b dI_a/dC (x) dI_b/dC of the tangent",
    "gradient": "the second-gradient part 4 sum_a dW/dI_a d2I_a/dC2 of the tangent",
    "stress": "the stress S = 2 sum_a dW/dI_a dI_a/dC (in the force and the geometric term)",
}

#: Multiplier -> words: the simple slips of a written factor.
SCALED_FACTORS: Dict[float, str] = {
    2.0: "doubled",
    0.5: "halved",
    0.0: "left out",
    -1.0: "with its sign flipped",
}

#: For W = Psi(I1b, I2b) + U(J) (the isochoric form): which unknowns are the isochoric
#: energy's (Psi_1, Psi_2, Psi_11, Psi_12, Psi_22) and which the volumetric's (U', U'').
_ISOCHORIC_UNKNOWNS = np.array([True, True, False, True, True, True, False])

#: scope -> words: where the scaled piece sits (the isochoric form's two parts, or all).
SCOPES: Dict[str, str] = {
    "iso": " in the isochoric part's chain rule (Psi(I1b, I2b) taken through I1, I2 and J; the "
    "volumetric part right)",
    "vol": " in the volumetric part U(J) (the isochoric part right)",
    "all": "",
}


def scaled_words(piece: str, factor: float, scope: str) -> str:
    """One scaled piece in words (the slip an engineer can look for)."""
    if piece == "dI2" and factor == 2.0:
        text = "dJ/dC written J C^-1 where J/2 C^-1 belongs (the 1/2 of dJ/dC lost)"
    else:
        text = f"{SCALED_PIECES[piece]} {SCALED_FACTORS[factor]}"
    where = SCOPES[scope]
    if piece.startswith("dI"):  # a gradient enters S and the tangent's products alike
        where += ", in the stress and the tangent"
    return text + where


def _scopes(fit: PieceFit) -> Dict[str, np.ndarray]:
    """The scopes that ``fit`` can tell apart: name -> (k,) booleans over its used unknowns."""
    k = int(fit.used.sum())
    out = {"all": np.ones(k, dtype=bool)}
    if fit.form == "isochoric":
        iso = _ISOCHORIC_UNKNOWNS[fit.used]
        if iso.any() and (~iso).any():
            out["iso"], out["vol"] = iso, ~iso
    return out


def _scaled(g, h, dW, d2W, right, piece: str, factor: float, inside: np.ndarray):
    """(dS (k, m, 3, 3), dCC (k, m, 3, 3, 3, 3)) per unit of the unknowns (dW, d2W over the
    pieces g, h; ``right`` their correct (S, CC)): ``piece`` times ``factor`` for the unknowns
    ``inside`` ((k,) booleans), zero for the others.
    """
    weights = {"hessian": 1.0, "gradient": 1.0, "stress": 1.0}
    if piece in weights:
        weights[piece] = factor
    elif piece.startswith("d2I"):
        h = [factor * x if i == int(piece[3]) else x for i, x in enumerate(h)]
    else:
        g = [factor * x if i == int(piece[2]) else x for i, x in enumerate(g)]
    S, CC = stress_tangent(g, h, dW, d2W, **weights)
    dS, dCC = S - right[0], CC - right[1]
    dS[~inside], dCC[~inside] = 0.0, 0.0
    return dS, dCC


def scaled_predictions(t: CellTensors, fit: PieceFit):
    """Every scaled piece's (piece, factor, scope, dS (m, 3, 3), dCC (m, 3, 3, 3, 3)): the
    engine's minus the oracle's stress and tangent, where the fit determines it and it is not
    zero.
    """
    m = t.J.size
    g, h = _law(t)
    dW, d2W = _basis(t, fit.form, "", fit.used)
    right = stress_tangent(g, h, dW, d2W)
    for scope, inside in _scopes(fit).items():
        for piece in SCALED_PIECES:
            for factor in SCALED_FACTORS:
                L = design_columns(*_scaled(g, h, dW, d2W, right, piece, factor, inside))
                if not np.any(L):
                    continue
                d = determined_change(L, fit.x, fit.scale, fit.free)
                if d is not None:
                    yield (
                        piece,
                        factor,
                        scope,
                        d[:, :9].reshape(m, 3, 3),
                        d[:, 9:].reshape(m, 3, 3, 3, 3),
                    )


def stress_tangent_output(
    split: ElementSplit, dS_force: np.ndarray, dS_geometric: np.ndarray, dCC: np.ndarray
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """The split's force and stiffness with per-cell changes of the stress in the force
    (dS_force), of the stress in the geometric stiffness (dS_geometric) and of the material
    tangent (dCC), all (m, ...): f_a = -V0 F S D_a, K_ab = V0 (D_a F CC F D_b + D_a S D_b I).
    """
    V0, D, F = split.V0, split.D, split.F
    fe = split.fe - V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, dS_force, D)
    mat = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, dCC, F, D)
    geo = np.einsum("maI,mIL,mbL,kl->makbl", D, dS_geometric, D, EYE)
    Ke = split.Ke + (V0[:, None, None, None, None] * (mat + geo)).reshape(-1, 12, 12)
    return assemble(split.cells, split.n, fe, Ke)


def law_fit(t: CellTensors, generic: Optional[CellTensors]) -> Optional[PieceFit]:
    """The first form (isochoric, then invariants) that fits the oracle's (S, CC) at ``t``;
    its unknowns restricted to those that do not vanish at ``generic`` (the same law at a
    nearby state with distinct eigenvalues, or None): on a state with equal eigenvalues the
    law's unused derivatives (I2's in a law of I1 alone) would otherwise be left free.
    """
    for form in FORMS:
        used = None
        if generic is not None:
            wide = fit_pieces(generic, form)
            if wide.residual > FIT_TOL or np.any(wide.free):
                continue
            used = ~vanishing(wide, generic)
        fit = fit_pieces(t, form, used)
        if fit.residual <= FIT_TOL:
            return fit
    return None


def piece_findings(
    split: ElementSplit,
    t: CellTensors,
    matches: Callable[[np.ndarray, sp.csr_matrix], float],
    generic: Optional[CellTensors] = None,
    fit: Optional[PieceFit] = None,
    scaled: bool = True,
) -> List[Finding]:
    """The mistaken pieces whose prediction the engine matches; matches(f, K) returns the
    larger relative error of the engine against (f, K), or inf when it does not match;
    generic: the law at a nearby state with distinct eigenvalues (:func:`law_fit`); fit: the
    law's fit when made already (else :func:`law_fit` makes it); scaled: also try one piece
    times a simple number (:data:`SCALED_PIECES`) when no other mistake fits.
    """
    fit = law_fit(t, generic) if fit is None else fit
    if fit is None:
        return []
    trials = [("law", c, w, dict(law=c)) for c, w in LAW_MISTAKES.items()]
    if fit.form == "isochoric":
        trials += [("chain", c, w, dict(chain=c)) for c, w in CHAIN_MISTAKES.items()]
    found = []
    evidence = (
        "the oracle's stress and tangent per cell (from the element matrices, whose "
        f"sum is the oracle's to {split.residual:.1e}) fitted on the chain rule's "
        f"pieces ({fit.form} form, misfit {fit.residual:.1e}), "
    )
    for _, code, title, kw in trials:
        pred = predict(t, fit, **kw)
        if pred is None:
            continue
        dS, dCC = pred
        f, K = stress_tangent_output(split, dS, dS, dCC)
        left = matches(f, K)
        if np.isfinite(left):
            found.append(
                Finding(
                    f"derivative-{code}",
                    title,
                    FULL,
                    evidence + "that piece written wrongly and the rest kept: force and "
                    f"stiffness errors against your engine {left:.1e}",
                    {"piece": code, "form": fit.form, "residual": left},
                )
            )
    if found or not scaled:
        return found
    # A written factor slipped (a 2 of 4 d2W, the 1/2 of dJ/dC): one piece times a simple
    # number, tried only when no piece written another way fits, so that a slip above never
    # comes back as its own multiple.
    for piece, factor, scope, dS, dCC in scaled_predictions(t, fit):
        f, K = stress_tangent_output(split, dS, dS, dCC)
        left = matches(f, K)
        if np.isfinite(left):
            found.append(
                Finding(
                    f"derivative-scaled-{piece}",
                    scaled_words(piece, factor, scope),
                    FULL,
                    evidence + f"that piece times {factor:g} and the rest kept: force and "
                    f"stiffness errors against your engine {left:.1e}",
                    {"piece": piece, "factor": factor, "scope": scope, "residual": left},
                )
            )
    return found
