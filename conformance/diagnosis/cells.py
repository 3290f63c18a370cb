"""Cells skipped or counted twice in the assembly: an error localised to a few cells that is
those cells' own contributions, missing (engine = oracle - cell) or added again (+ cell).

Once the error is localised (:func:`conformance.diagnosis.diagnose.diagnose`, the cells whose
nodes carry all of it), the engine-minus-oracle force and stiffness are fitted as a combination
of those cells' element forces and matrices (MJED's, used only when their sum is the oracle's:
:func:`conformance.diagnosis.elements.element_split`). Coefficients -1 say a cell is missing,
+1 that it is counted twice, k that it is counted k + 1 times; a fit that leaves more than the
case's tolerance names nothing. Bounded: at most :data:`MAX_CELLS` cells, fitted through their
(cells x cells) Gram matrix on the sparse element contributions.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import assemble, element_split
from conformance.diagnosis.findings import FULL, OBSERVED, Finding
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["CellFit", "fit_cell_contributions", "cell_contribution_reading", "MAX_CELLS"]

#: Most cells fitted (the localised set); more names no single cell.
MAX_CELLS = 64

#: A coefficient this close to an integer is read as that many copies of the cell.
_INTEGER = 1e-6


@dataclass(frozen=True)
class CellFit:
    """cells (k,): the fitted cells; alpha (k,): engine - oracle = sum alpha_c (cell c's force,
    matrix); force, stiffness: the errors left after the fit (relative, the case's scales).
    """

    cells: np.ndarray
    alpha: np.ndarray
    force: float
    stiffness: float


def fit_cell_contributions(
    cells: np.ndarray,
    n: int,
    fe: np.ndarray,
    Ke: np.ndarray,
    df: np.ndarray,
    dK: sp.spmatrix,
    candidates: np.ndarray,
    s: Scales,
) -> Optional[CellFit]:
    """The combination of the ``candidates``' element forces fe (m, 4, 3) and matrices
    Ke (m, 12, 12) closest to df (n, 3) and dK (3n, 3n) (engine minus oracle), each entry
    weighted by the case's scales; None beyond :data:`MAX_CELLS` or without candidates.
    """
    candidates = np.asarray(candidates, dtype=np.int64)
    if candidates.size == 0 or candidates.size > MAX_CELLS:
        return None
    parts = [assemble(cells[[c]], n, fe[[c]], Ke[[c]]) for c in candidates]
    fs = [p[0].ravel() / s.force for p in parts]
    Ks = [p[1] / s.stiffness for p in parts]
    b_f = np.asarray(df).ravel() / s.force
    b_K = sp.csr_matrix(dK) / s.stiffness
    k = candidates.size
    G = np.empty((k, k))
    rhs = np.empty(k)
    for i in range(k):  # k <= MAX_CELLS: a Gram matrix of sparse element contributions
        rhs[i] = fs[i] @ b_f + Ks[i].multiply(b_K).sum()
        for j in range(i, k):
            G[i, j] = G[j, i] = fs[i] @ fs[j] + Ks[i].multiply(Ks[j]).sum()
    alpha = np.linalg.lstsq(G, rhs, rcond=None)[0]
    f_fit, K_fit = assemble(
        cells[candidates],
        n,
        alpha[:, None, None] * fe[candidates],
        alpha[:, None, None] * Ke[candidates],
    )
    e = errors(f_fit, K_fit, None, np.asarray(df), sp.csr_matrix(dK), 0.0, s)
    return CellFit(candidates, alpha, e.force, e.stiffness)


def _describe(fit: CellFit) -> List[str]:
    """Words for each cell whose coefficient is not zero."""
    out = []
    for c, a in zip(fit.cells, fit.alpha):
        r = round(float(a))
        if abs(a) <= _INTEGER:
            continue
        if abs(a - r) <= _INTEGER and r == -1:
            out.append(f"cell {c}'s contribution missing (the assembly skips it)")
        elif abs(a - r) <= _INTEGER and r >= 1:
            out.append(f"cell {c} counted {'twice' if r == 1 else f'{r + 1} times'}")
        else:
            out.append(f"cell {c}'s contribution scaled by {1 + a:.6g}")
    return out


def cell_contribution_reading(diag, ci, out, ref, s: Scales):
    """``diag`` whose first cause is an error localised to a few cells, with the cells named
    when the error is their contributions missing or repeated (the localisation kept as an
    observation); unchanged otherwise (no MJED split, or the fit does not agree).
    """
    lead = diag.causes[0] if diag.causes else None
    if lead is None or lead.code != "localised" or not lead.figures.get("cells"):
        return diag
    tol: Tolerances = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    fit = fit_cell_contributions(
        split.cells,
        split.n,
        split.fe,
        split.Ke,
        np.asarray(out.force) - ref.force,
        sp.csr_matrix(out.stiffness) - ref.stiffness,
        np.asarray(lead.figures["cells"]),
        s,
    )
    if fit is None or fit.force > tol.force or fit.stiffness > tol.stiffness:
        return diag
    words = _describe(fit)
    if not words:
        return diag
    finding = Finding(
        "cell-contribution",
        "; ".join(words),
        FULL,
        "engine - oracle is "
        + " + ".join(f"{a:+.6g} x [cell {c}]" for c, a in zip(fit.cells, fit.alpha))
        + f" (those cells' element force and matrix, MJED's, whose sum is the oracle's to "
        f"{split.residual:.1e}): left force error {fit.force:.1e}, stiffness error "
        f"{fit.stiffness:.1e}",
        {
            "cells": [int(c) for c in fit.cells],
            "coefficients": [float(a) for a in fit.alpha],
            "residual": max(fit.force, fit.stiffness),
        },
    )
    rest = [replace(f, strength=OBSERVED) if f is lead else f for f in diag.findings]
    return replace(diag, findings=[finding, *rest])
