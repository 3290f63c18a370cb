"""The first Piola stress P or its derivative A = dP/dF with an index or operand slip.

An engine in the invertible-FEM / graphics style (Irving, Teran and Fedkiw; Sifakis and Barbic)
forms F = Ds Dm^-1 (Ds, Dm the deformed and rest edge matrices, columns x_a - x_0 and
X_a - X_0), P and A per cell, often through the SVD F = U diag(sigma) V^T
(P = U diag(psi) V^T, A_iJkL = U_ia V_Jb U_kc V_Ld Ahat_abcd), flattens A to 9 x 9 and assembles

    f_a = -V0 P G_a,    K_ab,ik = V0 G_aJ A_iJkL G_bL,

G_a = dN_a/dX. Its slips are tested here on the oracle's own per-cell P and A
(:func:`conformance.diagnosis.elements.cell_piola` of the element split), each slip of
:data:`SLIPS` predicting the engine's P' and A' from them (NumPy, nothing fitted), assembled:

- **the SVD's right factor**: the third output of ``numpy.linalg.svd`` (V^T) used as V, in P
  and in rotating A back, in P alone or in A alone (P' = U Phat Vh^T = U Phat V, Phat = U^T P V
  the stress in the SVD basis; A' rotated back with Vh, Ahat = A rotated into the basis);
- **one rotation on the wrong index** of A's rotation back (U for V or V for U on one of the
  four indices);
- **the 9 x 9 flattening**: vec(F) column-major against a row-major dF/dx: both index pairs
  transposed (A_JiLk), or one pair (rows or columns only);
- **the derivative taken in Ds**: dP/dDs = A_iJkL Dm^-1_lL (F = Ds Dm^-1, e.g. differences that
  perturb Ds and recompute F) used as dP/dF, or the chain factor on the wrong index;
- **the difference quotient's divisor**: A doubled or halved (central differences divided by h
  instead of 2h, one-sided ones by 2h), named only with the signature of differences (below);
- **F formed with its operands reversed**: F' = Dm^-1 Ds = Dm^-1 F Dm (edges from the first
  node, or from the last as in Sifakis' notes), the material's P and A at F' (MJED on the cells
  exploded, :func:`conformance.diagnosis.routine_inputs.piola_at`) assembled with the right
  gradients.

A slip is named when its force and stiffness match the engine's within the case's tolerance
and its prediction is not the oracle's (where U = V or F is diagonal several slips predict the
oracle: they explain nothing there); several that match are said as ambiguous. A slip of a
tangent an engine gets by differences (``numerical``) may leave more, up to sqrt(u) of its own
stiffness (the round-off of differences at a step of sqrt(u) or more), and only when what it
leaves has their signature: not symmetric (:data:`ASYMMETRY`), as the round-off and truncation
of differences of P are and the tangent of any energy's stress is not; it is then said as
partly explaining, with what it leaves, and only where no slip matches within the tolerance.
The exact doubling or halving of the stiffness alone is the global factor's
(:mod:`conformance.diagnosis.diagnose`), so the divisor slips are named only so. The correct
reassembly must reproduce the split (a soundness check of the per-cell P and A: otherwise
nothing is claimed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    piola_element_forces,
    split_reading,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, ambiguous
from conformance.diagnosis.routine_inputs import piola_at
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "SlipCells",
    "slip_cells",
    "PiolaSlip",
    "SLIPS",
    "EdgeSlip",
    "EDGE_SLIPS",
    "ASYMMETRY",
    "NUMERICAL",
    "slip_output",
    "slip_findings",
    "piola_slip_reading",
]

#: What a differences tangent may leave, relative to its own stiffness: the round-off of
#: differences at a step of sqrt(u) or more (u the double unit round-off).
NUMERICAL = 2.0**-26.5

#: Least antisymmetric share ||R - R^T|| / (2 ||R||) of what a numerical slip leaves, R: for
#: noise about 0.7; the tangent of any energy's stress leaves a symmetric R (share 0).
ASYMMETRY = 0.25


def _t(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


@dataclass(frozen=True)
class SlipCells:
    """The oracle's per-cell quantities a slip is written in.

    P: (m, 3, 3) first Piola stress; A: (m, 3, 3, 3, 3) its derivative, A[i, J, k, L] =
    dP_iJ / dF_kL; F: (m, 3, 3); Bm: (m, 3, 3) Dm^-1 (row a: the shape gradient of node a + 1,
    Dm's columns X_a - X_0); U, Vh: (m, 3, 3) numpy.linalg.svd(F)'s first and third outputs
    (F = U diag(sigma) Vh, V = Vh^T); Ph: (m, 3, 3) U^T P V, the stress in the SVD basis;
    Ah: (m, 3, 3, 3, 3) A rotated into it.
    """

    P: np.ndarray
    A: np.ndarray
    F: np.ndarray
    Bm: np.ndarray
    U: np.ndarray
    Vh: np.ndarray
    Ph: np.ndarray
    Ah: np.ndarray

    @property
    def V(self) -> np.ndarray:
        return _t(self.Vh)


def slip_cells(split: ElementSplit) -> SlipCells:
    """The split's :class:`SlipCells`."""
    P, A = cell_piola(split)
    U, _, Vh = np.linalg.svd(split.F)
    V = _t(Vh)
    Ph = np.einsum("mia,miJ,mJb->mab", U, P, V)
    Ah = np.einsum("mia,mJb,mkc,mLd,miJkL->mabcd", U, V, U, V, A, optimize=True)
    return SlipCells(P, A, split.F, split.D[:, 1:, :], U, Vh, Ph, Ah)


def _rotated(c: SlipCells, R1, R2, R3, R4) -> np.ndarray:
    """A' = R1_ia R2_Jb R3_kc R4_Ld Ahat_abcd (m, 3, 3, 3, 3)."""
    return np.einsum("mia,mJb,mkc,mLd,mabcd->miJkL", R1, R2, R3, R4, c.Ah, optimize=True)


def _stress_vh(c: SlipCells) -> np.ndarray:
    """P' = U Phat Vh^T (= U Phat V): numpy's Vh = V^T used as V."""
    return c.U @ c.Ph @ c.V


def _tangent_vh(c: SlipCells) -> np.ndarray:
    return _rotated(c, c.U, c.Vh, c.U, c.Vh)


@dataclass(frozen=True)
class PiolaSlip:
    """code; words: the mistake as an engineer would fix it; stress, tangent: (cells) -> the
    engine's P' (m, 3, 3) and A' (m, 3, 3, 3, 3) (None: the right one); numerical: the slip of
    a tangent taken by differences (it may leave their round-off); noise_only: named only with
    the differences' signature left (the exact slip is another reading's).
    """

    code: str
    words: str
    stress: Optional[Callable[[SlipCells], np.ndarray]] = None
    tangent: Optional[Callable[[SlipCells], np.ndarray]] = None
    numerical: bool = False
    noise_only: bool = False


_VH = (
    "numpy.linalg.svd's third output Vh (= V^T) used as V (the right singular vectors "
    "transposed; F = U diag(sigma) V^T)"
)
_INDEX = ("first (i)", "second (J)", "third (k)", "last (L)")
_RIGHT_ROTATION = "UVUV"


def _rotation_slip(p: int) -> PiolaSlip:
    """The rotation back of A with the other SVD factor on index p."""
    right = _RIGHT_ROTATION[p]
    other = "V" if right == "U" else "U"
    names = list(_RIGHT_ROTATION)
    names[p] = other

    def tangent(c: SlipCells) -> np.ndarray:
        return _rotated(c, *(c.U if n == "U" else c.V for n in names))

    idx = "iJkL"[p]
    return PiolaSlip(
        f"svd-rotation-{idx}",
        "dP/dF rotated back from the SVD basis (F = U diag(sigma) V^T) with the wrong rotation "
        f"on its {_INDEX[p]} index: {other} where {right} belongs, A_iJkL = "
        + " ".join(f"{n}_{i}{a}" for n, i, a in zip(names, "iJkL", "abcd"))
        + " Ahat_abcd for U_ia V_Jb U_kc V_Ld Ahat_abcd (an einsum operand typo; the stress "
        "right)",
        tangent=tangent,
    )


def _in_Ds(code: str, how: str, contraction: str) -> PiolaSlip:
    """The tangent differentiated in Ds (F = Ds Dm^-1): A contracted with Dm^-1 as
    ``contraction`` says; may be taken by differences.
    """
    return PiolaSlip(
        code,
        "the tangent differentiated with respect to the deformed edge matrix Ds instead of F" + how,
        tangent=lambda c: np.einsum(contraction, c.A, c.Bm),
        numerical=True,
    )


def _divisor(factor: float, times: str, quotient: str, used: str, right: str) -> PiolaSlip:
    """A difference quotient divided by ``used`` instead of ``right``: A times ``factor``, named
    only with the differences' noise left (the exact factor is the global factor's).
    """
    return PiolaSlip(
        f"difference-over-{used}",
        f"dP/dF, hence the stiffness, {times} the right one while the force is right, and what "
        f"is left beside the factor is the noise of finite differences: {quotient} divided by "
        f"{used} instead of {right}",
        tangent=lambda c: factor * c.A,
        numerical=True,
        noise_only=True,
    )


_FLAT = "dP/dF flattened to a 9 x 9 matrix"


def _geometric_paired_wrongly(c: SlipCells) -> np.ndarray:
    """A with its geometric part delta_ik S_JL replaced by delta_iJ S_kL (S = F^-1 P)."""
    S = np.linalg.solve(c.F, c.P)
    eye = np.eye(3)
    right = np.einsum("ik,mJL->miJkL", eye, S)
    wrong = np.einsum("iJ,mkL->miJkL", eye, S)
    return c.A - right + wrong


#: The slips tried, each predicting the engine's P' and A' from the oracle's per-cell P and A.
SLIPS: Tuple[PiolaSlip, ...] = (
    PiolaSlip(
        "svd-vh",
        f"{_VH}, in the stress P = U diag(psi) V^T and in rotating dP/dF back from the SVD "
        "basis (the singular values, hence the energy, right)",
        stress=_stress_vh,
        tangent=_tangent_vh,
    ),
    PiolaSlip(
        "svd-vh-stress",
        f"{_VH} in the stress P = U diag(psi) V^T only (dP/dF rotated back right)",
        stress=_stress_vh,
    ),
    PiolaSlip(
        "svd-vh-tangent",
        f"{_VH} in rotating dP/dF back from the SVD basis only (the stress right)",
        tangent=_tangent_vh,
    ),
    *(_rotation_slip(p) for p in range(4)),
    PiolaSlip(
        "vec-column-major",
        f"{_FLAT} with vec(F) stacking F's columns (column-major, as in Sifakis' notes and "
        "Eigen) while dF/dx is built for the row-major vec (F_00, F_01, ...), or the reverse: "
        "both index pairs transposed, A_JiLk for A_iJkL",
        tangent=lambda c: c.A.transpose(0, 2, 1, 4, 3),
    ),
    PiolaSlip(
        "vec-column-major-rows",
        f"{_FLAT} with its rows in column-major order (vec(P) stacking P's columns) and its "
        "columns row-major: the first index pair transposed, A_JikL for A_iJkL",
        tangent=lambda c: c.A.transpose(0, 2, 1, 3, 4),
    ),
    PiolaSlip(
        "vec-column-major-columns",
        f"{_FLAT} with its columns in column-major order (vec(F) stacking F's columns) and its "
        "rows row-major: the second index pair transposed, A_iJLk for A_iJkL",
        tangent=lambda c: c.A.transpose(0, 1, 2, 4, 3),
    ),
    _in_Ds(
        "derivative-in-Ds",
        " (F = Ds Dm^-1, e.g. differences that perturb Ds and recompute F): dP/dDs = dP/dF Dm^-T, "
        "A_iJkL (Dm^-1)_lL, used as dP/dF (an extra Dm^-T factor)",
        "miJkL,mlL->miJkl",
    ),
    _in_Ds(
        "derivative-in-Ds-index",
        ", its chain factor Dm^-1 on the wrong index: A_iJkL (Dm^-1)_Ll used as dP/dF",
        "miJkL,mLl->miJkl",
    ),
    PiolaSlip(
        "geometric-index-pairing",
        "the geometric (initial-stress) part of dP/dF written delta_iJ S_kL where delta_ik S_JL "
        "belongs (A_iJkL = delta_ik S_JL + F_iM C_MJNL F_kN: an index string of an einsum "
        "paired wrongly)",
        tangent=_geometric_paired_wrongly,
    ),
    PiolaSlip(
        "minor-symmetrised",
        "dP/dF symmetrised in (i, J) and in (k, L), as if it had the minor symmetries of a "
        "small-strain elasticity tensor (it has none: the stiffness is no longer the Hessian)",
        tangent=lambda c: (
            0.25
            * (
                c.A
                + c.A.transpose(0, 2, 1, 3, 4)
                + c.A.transpose(0, 1, 2, 4, 3)
                + c.A.transpose(0, 2, 1, 4, 3)
            )
        ),
    ),
    _divisor(2.0, "twice", "a central-difference quotient (P(F + h) - P(F - h))", "h", "2h"),
    _divisor(0.5, "half", "a one-sided difference quotient (P(F + h) - P(F))", "2h", "h"),
)


@dataclass(frozen=True)
class EdgeSlip:
    """code; words; given(F (m, 3, 3), Bm (m, 3, 3) = Dm^-1) -> the engine's F' (m, 3, 3)."""

    code: str
    words: str
    given: Callable[[np.ndarray, np.ndarray], np.ndarray]


#: Dm's columns from the last node (X_0 - X_3, X_1 - X_3, X_2 - X_3) in those from the first:
#: Dm_last = Dm T.
_LAST = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -1.0, -1.0]])

_REVERSED = (
    "the deformation gradient formed as Dm^-1 Ds (the product order reversed) instead of "
    "Ds Dm^-1 (Ds, Dm the deformed and rest edge matrices{}); the force and stiffness "
    "assembled with the right shape gradients dF/dx"
)

#: The kinematic slips: the material's P and A evaluated at F' instead of F.
EDGE_SLIPS: Tuple[EdgeSlip, ...] = (
    EdgeSlip(
        "F-product-reversed",
        _REVERSED.format(", columns x_a - x_0"),
        lambda F, Bm: Bm @ F @ np.linalg.inv(Bm),
    ),
    EdgeSlip(
        "F-product-reversed-last",
        _REVERSED.format(", columns x_a - x_3 from the cell's last node"),
        lambda F, Bm: np.linalg.solve(_LAST, Bm @ F @ np.linalg.inv(Bm) @ _LAST),
    ),
)


def slip_output(
    split: ElementSplit, P: np.ndarray, A: np.ndarray
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """Force (n, 3) and stiffness of an engine assembling per-cell P (m, 3, 3) and A
    (m, 3, 3, 3, 3): f_a = -V0 P G_a, K_ab,ik = V0 G_aJ A_iJkL G_bL.
    """
    fe = piola_element_forces(split.V0, split.D, P)
    return assemble(split.cells, split.n, fe, tangent_element_matrices(split.V0, split.D, A))


def _asymmetry(R: sp.csr_matrix) -> float:
    """||R - R^T|| / (2 ||R||) (0 for R = 0)."""
    n = float(sparse_norm(R))
    return float(sparse_norm(R - R.T)) / (2.0 * n) if n > 0.0 else 0.0


def _judge(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.csr_matrix,
    prediction: Tuple[np.ndarray, sp.csr_matrix],
    s: Scales,
    tol: Tolerances,
    numerical: bool,
    noise_only: bool,
) -> Optional[Tuple[str, str, dict]]:
    """(strength, evidence, figures) of a prediction that matches the engine, else None: within
    ``tol`` (FULL; never for ``noise_only``), or for a ``numerical`` slip the force within and
    the stiffness within :data:`NUMERICAL` of the prediction's own, what is left not symmetric
    (:data:`ASYMMETRY`; PARTIAL). A prediction that is the oracle's within ``tol`` is none.
    """
    fv, Kv = prediction
    if not (np.all(np.isfinite(fv)) and np.all(np.isfinite(Kv.data))):
        return None
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    if tol.within(errors(fv, Kv, None, f0, K0, 0.0, s), energy=False):
        return None
    e = errors(f, K, None, fv, Kv, 0.0, s)
    left = f"force error {e.force:.1e}, stiffness error {e.stiffness:.1e}"
    figures = {"residual": max(e.force, e.stiffness)}
    if tol.within(e, energy=False) and not noise_only:
        return FULL, left, figures
    if not numerical or e.force > tol.force:
        return None
    R = (K - Kv).tocsr()
    own = float(sparse_norm(R)) / max(float(sparse_norm(Kv)), 1e-300)
    share = _asymmetry(R)
    if own > NUMERICAL or share < ASYMMETRY:
        return None
    evidence = (
        f"{left}; what is left is {own:.1e} of that stiffness and not symmetric (antisymmetric "
        f"share {share:.2f}): the round-off and truncation of finite differences of P, which the "
        "tangent of no energy's stress leaves"
    )
    return PARTIAL, evidence, {**figures, "left": own, "asymmetry": share}


def slip_findings(
    model: Any, points: np.ndarray
) -> Callable[[ElementSplit, np.ndarray, sp.spmatrix, Scales, Tolerances], List[Finding]]:
    """A finder (split, f, K, s, tol) -> findings for
    :func:`conformance.diagnosis.elements.split_reading`: the slips of :data:`SLIPS` and
    :data:`EDGE_SLIPS` (these through ``model`` at F' on the cells of ``points``) whose force
    and stiffness match the engine's (several: ambiguous); none when the right reassembly does
    not reproduce the split.
    """

    def finder(split, f, K, s, tol):
        K = sp.csr_matrix(K)
        with np.errstate(all="ignore"):
            c = slip_cells(split)
            f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
            right = errors(f0, K0, None, *slip_output(split, c.P, c.A), 0.0, s)
            if not tol.within(right, energy=False):
                return []  # the per-cell P and A do not reproduce the oracle: claim nothing
        how = (
            "the oracle's first Piola stress and its derivative per cell (from its element "
            f"split, whose sum is the oracle's to {split.residual:.1e}) so changed and assembled"
        )
        found = []
        for v in SLIPS:
            with np.errstate(all="ignore"):
                P = c.P if v.stress is None else v.stress(c)
                A = c.A if v.tangent is None else v.tangent(c)
                got = _judge(
                    split, f, K, slip_output(split, P, A), s, tol, v.numerical, v.noise_only
                )
            if got is not None:
                strength, left, figures = got
                figures["variant"] = v.code
                found.append(
                    Finding(f"piola-slip-{v.code}", v.words, strength, f"{how}: {left}", figures)
                )
        how_F = (
            "the material's first Piola stress and its derivative at that F' (MJED, whose sum "
            f"is the oracle's to {split.residual:.1e} on this case, on the cells so deformed), "
            "assembled with the right gradients and rest volumes"
        )
        for v in EDGE_SLIPS:
            with np.errstate(all="ignore"):
                F2 = v.given(split.F, c.Bm)
                if np.allclose(F2, split.F, rtol=0.0, atol=1e-14):
                    continue
                at = piola_at(model, points, split, F2)
                if at is None:
                    continue
                got = _judge(split, f, K, slip_output(split, *at), s, tol, False, False)
            if got is not None:
                strength, left, figures = got
                figures["variant"] = v.code
                found.append(
                    Finding(f"piola-slip-{v.code}", v.words, strength, f"{how_F}: {left}", figures)
                )
        # A slip matched within the tolerance outranks one matched only up to the differences'
        # round-off.
        found = [x for x in found if x.strength == FULL] or found
        return ambiguous(found, "their predictions differ by less than the tolerance here")

    return finder


def piola_slip_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the slip of P or A the engine matches
    named first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (slip_findings(ci.model, ci.points),))
