"""A fibre-frame routine whose results are rotated back to the global axes wrongly, or a law
W(Q, J) of a fibre strain form with one of J's pieces wrong.

An engine for a fibre strain form Q = sum_ij B_ij Ef_ij^2 (Costa's) takes the strain into the
frame, Ef = R^T E R (R the per-cell frame, columns fibre, sheet, normal), computes the
derivatives of Q there, dQ/dEf / 2 = B o Ef (entrywise) and the constant T_f, and rotates them
back: dQ/dC = R (B o Ef) R^T and d2Q/dCdC = R R R R : T_f. A law W(Q, J) then has, by the chain
rule::

    S  = 2 (psi_Q dQ/dC + psi_J dJ/dC),
    CC = 4 (psi_QQ dQ (x) dQ + psi_QJ (dQ (x) dJ + dJ (x) dQ) + psi_JJ dJ (x) dJ
            + psi_Q d2Q + psi_J d2J).

The five derivatives psi are not taken from a material's code: per cell they are fitted on the
oracle's S and CC (:mod:`conformance.diagnosis.invariant_pieces`' machinery), which must be
reproduced to round-off (else the law is not of this form and nothing is claimed). Each way of
rotating back wrongly (:data:`ROTATIONS_BACK`) replaces dQ/dC and d2Q/dCdC in S and CC alike and
predicts the engine's force and stiffness with nothing else fitted; so does each of J's pieces
written wrongly (:data:`conformance.diagnosis.invariant_pieces.J_MISTAKES`: dJ/dC without its
J, say, in S and in CC's chain-rule products alike). One is named when its prediction matches
the engine within the case's tolerance (and is determined by the fit).
"""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit
from conformance.diagnosis.fibre_tangent import strain_form
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.invariant_pieces import (
    FIT_TOL,
    J_MISTAKES,
    LAW_MISTAKES,
    CellTensors,
    design_columns,
    determined_change,
    fit_columns,
    j_pieces,
    stress_tangent,
    stress_tangent_output,
)

__all__ = ["ROTATIONS_BACK", "PUSHES_FORWARD", "q_pieces", "fibre_piece_findings"]

_EYE = np.eye(3)

#: code -> (words, the einsum specs rotating a frame tensor of second and of fourth order back
#: with R, None: not rotated at all); the right one is R X R^T.
ROTATIONS_BACK: Dict[str, Tuple[str, Optional[str], Optional[str]]] = {
    "right": ("", "mia,mab,mjb->mij", "mia,mjb,mkc,mld,mabcd->mijkl"),
    "transposed": (
        "fibre-frame results (dQ/dC and d2Q/dCdC of the fibre strain form) rotated back to the "
        "global axes with the transpose of the frame, R^T (.) R (R^T on every index of the "
        "tangent) instead of R (.) R^T, the strain taken into the frame correctly (R^T E R)",
        "mai,mab,mbj->mij",
        "mai,mbj,mck,mdl,mabcd->mijkl",
    ),
    "not-rotated": (
        "fibre-frame results (dQ/dC and d2Q/dCdC of the fibre strain form) never rotated back "
        "to the global axes: used in the frame's components as if global, the strain taken "
        "into the frame correctly (R^T E R)",
        None,
        None,
    ),
}


#: code -> (words, H (m, 3, 3) from the cell tensors and the frame R: a spatial engine that
#: pushes the frame forward as a_i = G r_i for F r_i builds, pulled back, H dQ/dC H^T and
#: H H H H : d2Q/dCdC with H = F^-1 G, while Q itself (from R^T E R) is right).
PUSHES_FORWARD: Dict[str, Tuple[str, Callable[[CellTensors, np.ndarray], np.ndarray]]] = {
    "covectors": (
        "the fibre frame pushed forward as covectors, a_i = F^-T r_i (a surface normal's "
        "push-forward), where the fibre directions are material line elements, a_i = F r_i, "
        "in F M F^T and the tangent's dyads (Q itself right)",
        lambda t, R: t.Ci,
    ),
    "normalised": (
        "the pushed-forward frame vectors a_i = F r_i normalised to unit length before "
        "F M F^T and the tangent's dyads are formed (their stretch belongs in them; Q itself "
        "right)",
        lambda t, R: np.einsum(
            "mia,ma,mja->mij", R, 1.0 / np.sqrt(np.einsum("mia,mij,mja->ma", R, t.C, R)), R
        ),
    ),
    "isochoric": (
        "the fibre frame pushed forward with the isochoric F_bar = J^(-1/3) F, a_i = F_bar r_i, "
        "in F M F^T and the tangent's dyads while the J^(-4/3) of the isochoric Q is kept too "
        "(Q itself right)",
        lambda t, R: (t.J ** (-1.0 / 3.0))[:, None, None] * np.broadcast_to(_EYE, t.C.shape),
    ),
}


def q_pieces(
    t: CellTensors, B: np.ndarray, R: np.ndarray, back: str = "right", push: str = ""
) -> Tuple[np.ndarray, np.ndarray]:
    """dQ/dC (m, 3, 3) and d2Q/dCdC (m, 3, 3, 3, 3) of Q = sum B_ij (R^T E R)_ij^2, rotated back
    as ``back`` (a key of :data:`ROTATIONS_BACK`), and through a frame pushed forward as
    ``push`` says (a key of :data:`PUSHES_FORWARD`; "": as F r_i). B: (3, 3); R: (m, 3, 3).
    """
    if push:
        g, h = q_pieces(t, B, R, back)
        H = PUSHES_FORWARD[push][1](t, R)
        return (
            np.einsum("mia,mab,mjb->mij", H, g, H),
            np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", H, H, H, H, h, optimize=True),
        )
    Ef = np.einsum("mai,mab,mbj->mij", R, 0.5 * (t.C - _EYE), R)
    Tf = 0.25 * (
        np.einsum("ab,ac,bd->abcd", B, _EYE, _EYE) + np.einsum("ab,ad,bc->abcd", B, _EYE, _EYE)
    )
    Tf = np.broadcast_to(Tf, R.shape[:1] + Tf.shape)
    _, two, four = ROTATIONS_BACK[back]
    if two is None or four is None:
        return B * Ef, np.array(Tf)
    return np.einsum(two, R, B * Ef, R), np.einsum(four, R, R, R, R, Tf, optimize=True)


def _columns(
    t: CellTensors, B: np.ndarray, R: np.ndarray, back: str, j_mistake: str = "", push: str = ""
) -> np.ndarray:
    """(m, 90, 5) the design columns of psi_Q, psi_J, psi_QQ, psi_QJ, psi_JJ with dQ and d2Q
    rotated back as ``back`` and J's pieces with ``j_mistake`` (a code of
    :data:`conformance.diagnosis.invariant_pieces.J_MISTAKES`; "": none).
    """
    gQ, hQ = q_pieces(t, B, R, back, push)
    gJ, hJ = j_pieces(t, j_mistake)
    m = t.J.size
    dW = np.zeros((5, m, 2))
    d2W = np.zeros((5, m, 2, 2))
    dW[0, :, 0] = dW[1, :, 1] = 1.0
    d2W[2, :, 0, 0] = d2W[4, :, 1, 1] = 1.0
    d2W[3, :, 0, 1] = d2W[3, :, 1, 0] = 1.0
    return design_columns(*stress_tangent([gQ, gJ], [hQ, hJ], dW, d2W))


def fibre_piece_findings(
    split: ElementSplit,
    t: CellTensors,
    model: Any,
    matches: Callable[[np.ndarray, sp.csr_matrix], float],
) -> List[Finding]:
    """The wrong rotations back of :data:`ROTATIONS_BACK` whose prediction the engine matches
    (matches(f, K): the engine's larger error against (f, K), inf unless within the tolerance
    and not the oracle's own); none for a model without a fibre strain form or a law that is
    not W(Q, J) on this case.
    """
    form = strain_form(model, t.J.size)
    if form is None:
        return []
    B, R = form
    right = _columns(t, B, R, "right")
    x, scale, free, residual = fit_columns(right, t.S, t.CC)
    if residual > FIT_TOL:
        return []
    trials = [
        (f"fibre-rotated-back-{code}", words, "dQ/dC and d2Q/dCdC rotated back so", code, "", "")
        for code, (words, _, _) in ROTATIONS_BACK.items()
        if code != "right"
    ]
    trials += [
        (f"derivative-{code}", LAW_MISTAKES[code], "that piece of J written so", "right", code, "")
        for code in J_MISTAKES
    ]
    trials += [
        (f"fibre-pushed-{code}", words, "the frame so pushed forward", "right", "", code)
        for code, (words, _) in PUSHES_FORWARD.items()
    ]
    found = []
    for code, words, how, back, j_mistake, push in trials:
        d = determined_change(_columns(t, B, R, back, j_mistake, push) - right, x, scale, free)
        if d is None:
            continue
        m = t.J.size
        dS, dCC = d[:, :9].reshape(m, 3, 3), d[:, 9:].reshape(m, 3, 3, 3, 3)
        left = matches(*stress_tangent_output(split, dS, dS, dCC))
        if np.isfinite(left):
            found.append(
                Finding(
                    code,
                    words,
                    FULL,
                    "the oracle's stress and tangent per cell (from the element matrices, whose "
                    f"sum is the oracle's to {split.residual:.1e}) fitted on the chain rule of "
                    f"W(Q, J) (misfit {residual:.1e}), {how} and the rest kept: force and "
                    f"stiffness errors against your engine {left:.1e}",
                    {"rotation": back, "j_piece": j_mistake, "push": push, "residual": left},
                )
            )
    return found
