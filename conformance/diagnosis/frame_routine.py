"""A fibre-frame strain routine's results taken back to the global axes wrongly by its driver.

Anisotropic laws given per cell in a fibre frame R (columns fibre, sheet, normal) are often
written as a routine of the Green-Lagrange strain in that frame (Abaqus' UANISOHYPER_STRAIN
manner): the driver hands it Ef = R^T E R as six Voigt components (11, 22, 33, 23, 13, 12,
engineering shears), the routine returns the stress Sf = dU/dEf (six entries) and the tangent
Df = d2U/dEf2 (a 6 x 6 matrix, or its 21-entry packed triangle), and the driver rotates them
back, S = R Sf R^T and CC_IJKL = R_Ia R_Jb R_Kc R_Ld Df_abcd. What changes between such engines
is the bookkeeping, and that is where they go wrong:

- the tangent left in the frame's components (used as if global), or rotated back with R^T;
- the packed triangle unpacked in another order than it was packed (row by row against column
  by column), or the 6 x 6 read in another order of the shear components;
- the shear entries taken in the other shear convention (a derivative by a tensor component
  E_ij, with E_ji moved alike, is twice the derivative by the engineering shear 2 E_ij): the
  stress's shear entries doubled or halved, the tangent's normal-shear entries by that factor
  and its shear-shear entries by its square.

The oracle's stress and material tangent per cell (read from its element arrays,
:func:`conformance.diagnosis.invariant_pieces.cell_tensors`) are taken into the frame, changed
as each slip changes them, and taken back; each slip so predicts the engine's force (through S)
and stiffness (material part through CC, geometric part through S) with nothing fitted. One is
named when its prediction matches the engine within the tolerances. Only models with a per-cell
frame (``model.frame``). NumPy and MJED only.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    element_split,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["VOIGT", "Slip", "frame_slips", "frame_routine_findings", "frame_routine_reading"]

#: The routine's Voigt order of the frame components (engineering shears).
VOIGT: Tuple[Tuple[int, int], ...] = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
_NORMAL, _SHEAR = np.arange(3), np.arange(3, 6)

#: The 21-entry packings of a symmetric 6 x 6: its upper triangle row by row, and column by
#: column (LAPACK's "U" packed storage).
ROW_WISE = tuple((i, j) for i in range(6) for j in range(i, 6))
COLUMN_WISE = tuple((i, j) for j in range(6) for i in range(j + 1))


@dataclass(frozen=True)
class Slip:
    """One slip: its words, and what it does to the frame stress Sf (m, 6) and tangent Df
    (m, 6, 6) in Voigt form, or to the rotation back ("frame": not rotated, "transpose": with
    R^T).
    """

    words: str
    stress: Any = None
    tangent: Any = None
    back: str = "right"


def _voigt(T2: np.ndarray) -> np.ndarray:
    return np.stack([T2[:, i, j] for i, j in VOIGT], axis=1)


def _tensor2(v: np.ndarray) -> np.ndarray:
    out = np.zeros((v.shape[0], 3, 3))
    for A, (i, j) in enumerate(VOIGT):
        out[:, i, j] = out[:, j, i] = v[:, A]
    return out


def _voigt4(T4: np.ndarray) -> np.ndarray:
    i = np.array([p[0] for p in VOIGT])
    j = np.array([p[1] for p in VOIGT])
    return T4[:, i[:, None], j[:, None], i[None, :], j[None, :]]


def _tensor4(D: np.ndarray) -> np.ndarray:
    out = np.zeros((D.shape[0], 3, 3, 3, 3))
    for A, (i, j) in enumerate(VOIGT):
        for B, (k, l) in enumerate(VOIGT):
            for a, b in {(i, j), (j, i)}:
                for c, d in {(k, l), (l, k)}:
                    out[:, a, b, c, d] = D[:, A, B]
    return out


def _unpacked(D: np.ndarray, written, read) -> np.ndarray:
    """D (m, 6, 6) packed as ``written`` and unpacked as ``read`` (symmetric fill)."""
    out = np.zeros_like(D)
    for (i, j), (k, l) in zip(written, read):
        out[:, k, l] = out[:, l, k] = D[:, i, j]
    return out


def _shear_order(perm) -> Any:
    order = np.concatenate([_NORMAL, _SHEAR[list(perm)]])
    return lambda D: D[:, order][:, :, order]


def _shear_scaled(k: float) -> Tuple[Any, Any]:
    def stress(S):
        out = S.copy()
        out[:, _SHEAR] *= k
        return out

    def tangent(D):
        out = D.copy()
        out[:, _SHEAR, :] *= k
        out[:, :, _SHEAR] *= k
        return out

    return stress, tangent


def frame_slips() -> List[Slip]:
    """The slips of the module's docstring, in order."""
    out = [
        Slip(
            "the routine's tangent d2U/dEf2 used in the fibre frame's components as if global "
            "(never rotated back to the axes, R R R R : Df), the stress rotated back right",
            back="frame",
        ),
        Slip(
            "the routine's tangent rotated back with the transpose of the frame (R^T on every "
            "index of Df), the stress rotated back right",
            back="transpose",
        ),
        Slip(
            "the routine's 21-entry packed tangent d2U/dEf2, written as its upper triangle row "
            "by row, unpacked column by column (LAPACK's packed storage): its entries out of "
            "place",
            tangent=lambda D: _unpacked(D, ROW_WISE, COLUMN_WISE),
        ),
        Slip(
            "the routine's 21-entry packed tangent d2U/dEf2, written as its upper triangle "
            "column by column, unpacked row by row: its entries out of place",
            tangent=lambda D: _unpacked(D, COLUMN_WISE, ROW_WISE),
        ),
    ]
    names = ("23", "13", "12")
    for perm in itertools.permutations(range(3)):
        if perm == (0, 1, 2):
            continue
        out.append(
            Slip(
                "the routine's 6 x 6 tangent d2U/dEf2 read with its shear components in the "
                f"order {', '.join(names[p] for p in perm)} where it has 23, 13, 12",
                tangent=_shear_order(perm),
            )
        )
    for k, said in ((2.0, "doubled"), (0.5, "halved")):
        stress, tangent = _shear_scaled(k)
        conv = (
            "a derivative by the tensor shear E_ij (E_ji moved alike) taken for one by the "
            "engineering shear 2 E_ij"
            if k == 2.0
            else "a derivative by the engineering shear 2 E_ij taken for one by the tensor "
            "shear E_ij"
        )
        out.append(
            Slip(
                f"the routine's frame stress dU/dEf with its shear entries {said} ({conv}), "
                "the tangent right",
                stress=stress,
            )
        )
        out.append(
            Slip(
                f"the routine's frame tangent d2U/dEf2 in the other shear convention ({conv}): "
                f"its normal-shear entries {said}, its shear-shear entries by {k * k:g}, the "
                "stress right",
                tangent=tangent,
            )
        )
        out.append(
            Slip(
                f"the routine's frame stress and tangent in the other shear convention ({conv}): "
                f"shear stresses {said}, normal-shear tangent entries {said}, shear-shear by "
                f"{k * k:g}",
                stress=stress,
                tangent=tangent,
            )
        )
    return out


def _to_frame(T2, T4, R):
    return (
        np.einsum("mIa,mIJ,mJb->mab", R, T2, R),
        np.einsum("mIa,mJb,mKc,mLd,mIJKL->mabcd", R, R, R, R, T4, optimize=True),
    )


def _back(T2, T4, R, how: str):
    Q = R.swapaxes(1, 2) if how == "transpose" else R
    S = np.einsum("mIa,mab,mJb->mIJ", R, T2, R)
    if how == "frame":
        return S, T4
    return S, np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", Q, Q, Q, Q, T4, optimize=True)


def frame_routine_findings(
    split: ElementSplit, model: Any, out, f_o: np.ndarray, K_o, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The findings naming a slip of :func:`frame_slips` whose prediction matches the engine
    (several distinct: ambiguous); [] for a model without a per-cell frame.
    """
    frame = getattr(model, "frame", None)
    if frame is None:
        return []
    m = split.cells.shape[0]
    R = np.asarray(frame, dtype=np.float64)
    R = np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R.reshape(m, 3, 3)
    t = cell_tensors(*cell_piola(split), split.F)
    Sf, CCf = _to_frame(t.S, t.CC, R)
    Sv, Dv = _voigt(Sf), _voigt4(CCf)
    F = split.F
    found = []
    for slip in frame_slips():
        S2 = _tensor2(slip.stress(Sv)) if slip.stress is not None else Sf
        T4 = _tensor4(slip.tangent(Dv)) if slip.tangent is not None else CCf
        S, CC = _back(S2, T4, R, slip.back)
        dS, dCC = S - t.S, CC - t.CC
        A = np.einsum("mkJ,mJIML,mlM->mkIlL", F, dCC, F, optimize=True)
        A = A + np.einsum("kl,mLI->mkIlL", np.eye(3), dS)
        fe = piola_element_forces(split.V0, split.D, F @ dS)
        df, dK = assemble(split.cells, split.n, fe, tangent_element_matrices(split.V0, split.D, A))
        e = errors(out.force, out.stiffness, None, f_o + df, K_o + dK, 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    "frame-routine",
                    f"a fibre-frame strain routine's results taken back wrongly: {slip.words}",
                    FULL,
                    "the oracle's stress and material tangent per cell, taken into the kit's "
                    "fibre frame (Ef = R^T E R; Voigt 11, 22, 33, 23, 13, 12, engineering "
                    "shears), changed as this slip changes them and taken back, predict your "
                    f"force to {e.force:.1e} and your stiffness to {e.stiffness:.1e}, nothing "
                    "fitted",
                    {"slip": slip.words},
                )
            )
    return ambiguous(found) if len(found) > 1 else found


def frame_routine_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with a fibre-frame routine's slip named
    first; unchanged when none matches or the model has no frame.
    """
    if getattr(ci.model, "frame", None) is None:
        return diag
    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    with np.errstate(all="ignore"):
        found = frame_routine_findings(
            split, ci.model, out, ref.force, sp.csr_matrix(ref.stiffness), s, tol
        )
    return named_first(diag, found)
