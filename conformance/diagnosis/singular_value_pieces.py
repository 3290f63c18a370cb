"""An SVD engine's dPsi/dsigma with one invariant's derivative by the singular values wrong.

Invertible-FEM engines (Irving, Teran and Fedkiw 2004; Teran et al. 2005; Sifakis and Barbic
2012) write an isotropic energy as a function of the singular values sigma of
F = U diag(sigma) V^T through the invariants I1 = sum sigma_i^2,
I2 = sum_{i<j} sigma_i^2 sigma_j^2 and J = sigma_1 sigma_2 sigma_3, and carry each invariant
with its gradient dI/dsigma, its Hessian and the divided differences
(dI/dsigma_i - dI/dsigma_j)/(sigma_i - sigma_j) of its gradient. The stress is
P = U diag(psi) V^T with psi_i = dPsi/dsigma_i = sum_a W_a dI_a/dsigma_i (W_a = dW/dI_a), and
dP/dF in the SVD basis is Teran's blocks: the 3x3 block d2Psi/dsigma2 and, per pair (i, j), the
2x2 block of a = (minus + plus)/2, b = (minus - plus)/2, with
minus = (psi_i - psi_j)/(sigma_i - sigma_j) (from the divided differences: sum_a W_a dd_a) and
plus = (psi_i + psi_j)/(sigma_i + sigma_j) (from the stress).

One invariant's piece written wrongly moves the output by a change fixed once W_a is known:

- its gradient dI_a/dsigma (by a factor, or its chain factor dropped: dW/dI_a used for its part
  of dPsi/dsigma_i): the stress and the plus quotient take the wrong psi; the 3x3 block and the
  minus quotient, carried separately, are right;
- its divided difference (by a factor): the minus quotient alone, the stiffness only.

W_a is not taken from a material's code: per cell, the oracle's stress and tangent are fitted on
the chain rule's pieces (:func:`conformance.diagnosis.invariant_pieces.law_fit`), and a change
is predicted only where that fit determines it. A piece is named when its prediction brings
the engine's force and stiffness within the case's tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.invariant_pieces import (
    CellTensors,
    PieceFit,
    derivative_basis,
    determined_change,
)

__all__ = [
    "INVARIANTS",
    "Slip",
    "SLIPS",
    "rotation_variant_svd",
    "sigma_jets",
    "block_change",
    "slip_columns",
    "slip_output",
    "singular_value_findings",
]

#: The pairs (i, j) of Teran's 2x2 blocks, and the index k in neither.
PAIRS = ((0, 1), (0, 2), (1, 2))
THIRD = (2, 1, 0)

#: invariant -> (its definition, its gradient by sigma_i, its divided difference for (i, j)).
INVARIANTS: Dict[str, Tuple[str, str, str]] = {
    "I1": ("I1 = sum sigma_i^2", "2 sigma_i", "2"),
    "I2": (
        "I2 = sum_{i<j} sigma_i^2 sigma_j^2",
        "2 sigma_i (I1 - sigma_i^2)",
        "2 (sigma_k^2 - sigma_i sigma_j)",
    ),
    "J": ("J = sigma_1 sigma_2 sigma_3", "J/sigma_i", "-sigma_k"),
}

#: factor -> words, for a piece written with a constant factor.
FACTORS: Dict[float, str] = {
    -1.0: "with its sign flipped",
    0.0: "left out",
    0.5: "halved",
    2.0: "doubled",
}


@dataclass(frozen=True)
class Slip:
    """One invariant's piece written wrongly: invariant (a key of :data:`INVARIANTS`), place
    ("gradient": dI/dsigma in the stress and the plus quotient; "difference": the divided
    difference in the minus quotient), factor (the piece times it; None: the chain factor
    dI/dsigma_i dropped, i.e. taken as 1), carried (a gradient slip only: the 3x3 block's
    chain-rule products d2W/dI_a dI_b (dI_a/dsigma (x) dI_b/dsigma) take the wrong gradient
    too, as jets or forward-mode differentiation carry it).
    """

    invariant: str
    place: str
    factor: Optional[float]
    carried: bool = False

    @property
    def code(self) -> str:
        how = "dropped" if self.factor is None else f"{self.factor:g}"
        return f"sigma-{self.place}-{self.invariant}-{how}" + ("-carried" if self.carried else "")

    @property
    def title(self) -> str:
        name, grad, dd = INVARIANTS[self.invariant]
        i = self.invariant
        if self.place == "difference":
            return (
                f"the divided difference (d{i}/dsigma_i - d{i}/dsigma_j)/(sigma_i - sigma_j) = "
                f"{dd} of {name} {FACTORS[self.factor]} in the (psi_i - psi_j)/(sigma_i - "
                "sigma_j) quotient of your SVD-basis 2x2 blocks (Teran's), in every term "
                f"through {i}: stiffness only (sigma the singular values of F, psi_i = "
                "dPsi/dsigma_i)"
            )
        if self.factor is None:
            what = (
                f"the chain factor d{i}/dsigma_i = {grad} dropped from dPsi/dsigma_i (dPsi/d{i} "
                f"used for its part of dPsi/dsigma_i, {name})"
            )
        else:
            what = (
                f"d{i}/dsigma_i = {grad}, the derivative of {name} by the singular values, "
                f"{FACTORS[self.factor]} in dPsi/dsigma_i"
            )
        hessian = (
            "the chain rule's products in the 3x3 block d2Psi/dsigma2 take it too (as jets "
            f"carry it), d2{i}/dsigma2 itself and the (psi_i - psi_j)/(sigma_i - sigma_j) "
            "quotient right"
            if self.carried
            else "the 3x3 block d2Psi/dsigma2 and the (psi_i - psi_j)/(sigma_i - sigma_j) "
            "quotient right"
        )
        return (
            f"{what}, in every term through {i}: your stress P = U diag(dPsi/dsigma) V^T and "
            "the (psi_i + psi_j)/(sigma_i + sigma_j) quotient of your SVD-basis 2x2 blocks take "
            f"it ({hessian})"
        )


#: The slips tried: each invariant's gradient by each factor or its chain factor dropped (the
#: 3x3 block right, or its chain-rule products carrying the wrong gradient), and its divided
#: difference by each factor.
SLIPS: Tuple[Slip, ...] = tuple(
    [
        Slip(i, "gradient", k, carried)
        for i in INVARIANTS
        for k in (*FACTORS, None)
        for carried in (False, True)
    ]
    + [Slip(i, "difference", k) for i in INVARIANTS for k in FACTORS]
)


def rotation_variant_svd(F: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F (m, 3, 3) = U diag(s) V^T with U, V (m, 3, 3) proper rotations, s (m, 3) (a
    reflection put on s[:, 2]).
    """
    U, s, Vt = np.linalg.svd(F)
    V = Vt.swapaxes(1, 2).copy()
    U, s = U.copy(), s.copy()
    for R in (U, V):
        flip = np.linalg.det(R) < 0
        R[flip, :, 2] *= -1.0
        s[flip, 2] *= -1.0
    return U, s, V


def _pair(s: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    i, j = zip(*PAIRS)
    return s[:, list(i)], s[:, list(j)], s[:, list(THIRD)]


def sigma_jets(s: np.ndarray) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """Invariant -> (its gradient by sigma (m, 3), its divided differences over PAIRS (m, 3))
    at the singular values s (m, 3).
    """
    si, sj, sk = _pair(s)
    s2 = s * s
    I1 = s2.sum(axis=1)[:, None]
    gJ = np.stack([s[:, 1] * s[:, 2], s[:, 0] * s[:, 2], s[:, 0] * s[:, 1]], axis=1)
    return {
        "I1": (2.0 * s, np.full_like(s, 2.0)),
        "I2": (2.0 * s * (I1 - s2), 2.0 * (sk * sk - si * sj)),
        "J": (gJ, -sk),
    }


def block_change(
    U: np.ndarray,
    s: np.ndarray,
    V: np.ndarray,
    dpsi: np.ndarray,
    dminus: np.ndarray,
    dH: np.ndarray,
) -> Tuple[np.ndarray, np.ndarray]:
    """(dP (..., m, 3, 3), dA (..., m, 3, 3, 3, 3)) of a change dpsi (..., m, 3) of the stress's
    psi (which the plus quotient takes), dminus (..., m, 3) of the minus quotients over PAIRS
    and dH (..., m, 3, 3) of the 3x3 block, rotated back by U, V (m, 3, 3);
    A[k, I, l, L] = dP_kI/dF_lL.
    """
    lead = dpsi.shape[:-1]
    Ah = np.zeros((*lead, 3, 3, 3, 3))
    for i in range(3):
        for j in range(3):
            Ah[..., i, i, j, j] = dH[..., i, j]
    for n, (i, j) in enumerate(PAIRS):
        dplus = (dpsi[..., i] + dpsi[..., j]) / (s[:, i] + s[:, j])
        a = 0.5 * (dminus[..., n] + dplus)
        b = 0.5 * (dminus[..., n] - dplus)
        Ah[..., i, j, i, j] = Ah[..., j, i, j, i] = a
        Ah[..., i, j, j, i] = Ah[..., j, i, i, j] = b
    dP = np.einsum("mia,...ma,mja->...mij", U, dpsi, V)
    dA = np.einsum("mka,mIb,mlc,mLd,...mabcd->...mkIlL", U, V, U, V, Ah, optimize=True)
    return dP, dA


def slip_columns(
    slip: Slip,
    U: np.ndarray,
    s: np.ndarray,
    V: np.ndarray,
    dW: np.ndarray,
    d2W: np.ndarray,
) -> np.ndarray:
    """(m, 90, k) the change of (P, dP/dF) per cell that ``slip`` makes per unit of each of k
    unknowns whose derivatives of W by (I1, I2, J) are dW (k, m, 3) and d2W (k, m, 3, 3).
    """
    jets = sigma_jets(s)
    a = tuple(INVARIANTS).index(slip.invariant)
    grad, dd = jets[slip.invariant]
    k, m = dW.shape[:2]
    dpsi = np.zeros((k, m, 3))
    dminus = np.zeros((k, m, 3))
    dH = np.zeros((k, m, 3, 3))
    if slip.place == "difference":
        dminus = dW[:, :, a, None] * ((slip.factor - 1.0) * dd)
    else:
        delta = 1.0 - grad if slip.factor is None else (slip.factor - 1.0) * grad
        dpsi = dW[:, :, a, None] * delta
        if slip.carried:
            G = np.stack([jets[name][0] for name in INVARIANTS])  # (3, m, 3)
            Gw = G.copy()
            Gw[a] += delta
            products = np.einsum("ami,bmj->mabij", Gw, Gw) - np.einsum("ami,bmj->mabij", G, G)
            dH = np.einsum("kmab,mabij->kmij", d2W, products)
    dP, dA = block_change(U, s, V, dpsi, dminus, dH)
    return np.concatenate([dP.reshape(k, m, 9), dA.reshape(k, m, 81)], axis=2).transpose(1, 2, 0)


def slip_output(
    split: ElementSplit, dP: np.ndarray, dA: np.ndarray
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """The split's force and stiffness with per-cell changes dP (m, 3, 3) of the first Piola
    stress and dA (m, 3, 3, 3, 3) of dP/dF: f_a = -V0 P D_a, K_ab = V0 D_a . A . D_b.
    """
    fe = split.fe + piola_element_forces(split.V0, split.D, dP)
    Ke = split.Ke + tangent_element_matrices(split.V0, split.D, dA)
    return assemble(split.cells, split.n, fe, Ke)


def singular_value_findings(
    split: ElementSplit,
    t: CellTensors,
    fit: Optional[PieceFit],
    matches: Callable[[np.ndarray, sp.csr_matrix], float],
) -> List[Finding]:
    """The slips (:data:`SLIPS`) whose prediction the engine matches; fit: the law's
    derivatives fitted per cell (:func:`conformance.diagnosis.invariant_pieces.law_fit`; None:
    the law is not of that form, nothing is claimed); matches(f, K): the engine's larger
    relative error against (f, K), inf when it does not match.
    """
    if fit is None or np.any(np.linalg.det(t.F) <= 0):
        return []
    U, s, V = rotation_variant_svd(t.F)
    dW, d2W = derivative_basis(t, fit)
    m = t.J.size
    found = []
    for slip in SLIPS:
        if slip.carried and not np.any(d2W):
            continue
        L = slip_columns(slip, U, s, V, dW, d2W)
        d = determined_change(L, fit.x, fit.scale, fit.free)
        if d is None:
            continue
        f, K = slip_output(split, d[:, :9].reshape(m, 3, 3), d[:, 9:].reshape(m, 3, 3, 3, 3))
        left = matches(f, K)
        if np.isfinite(left):
            found.append(
                Finding(
                    slip.code,
                    slip.title,
                    FULL,
                    "the oracle's stress and tangent per cell (from the element matrices, whose "
                    f"sum is the oracle's to {split.residual:.1e}) fitted on the chain rule's "
                    f"pieces for dW/d{slip.invariant} ({fit.form} form, misfit "
                    f"{fit.residual:.1e}); that piece written so in the SVD-basis stress and "
                    f"blocks, the rest kept: force and stiffness errors against your engine "
                    f"{left:.1e}",
                    {
                        "invariant": slip.invariant,
                        "place": slip.place,
                        "factor": slip.factor,
                        "residual": left,
                    },
                )
            )
    return found
