"""Cells skipped or counted twice in the assembly: an error localised to a few cells that is
those cells' own contributions, missing (engine = oracle - cell) or added again (+ cell).

Once the error is localised (:func:`conformance.diagnosis.diagnose.diagnose`, the cells whose
nodes carry all of it), the engine-minus-oracle force and stiffness are fitted as a combination
of those cells' element forces and matrices (MJED's, used only when their sum is the oracle's:
:func:`conformance.diagnosis.elements.element_split`). Coefficients -1 say a cell is missing,
+1 that it is counted twice, k that it is counted k + 1 times; a fit that leaves more than the
case's tolerance names nothing. Bounded: at most :data:`MAX_CELLS` cells, fitted through their
(cells x cells) Gram matrix on the sparse element contributions.

Cells missing here and there (the error not localised: the last few cells of an unstructured
mesh lie all over it) are fitted all at once, one coefficient a cell, by the normal equations
of the sparse design matrix (:func:`fit_all_cells`; meshes up to :data:`MAX_ALL_CELLS` cells),
and named only when fewer than half of the cells are off.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, element_split
from conformance.diagnosis.findings import FULL, OBSERVED, Finding
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "stiffest_cells",
    "CellFit",
    "fit_cell_contributions",
    "fit_all_cells",
    "cell_contribution_reading",
    "spread_cells_reading",
    "MAX_CELLS",
    "MAX_ALL_CELLS",
]

#: Most cells fitted one by one (the localised set).
MAX_CELLS = 64

#: Most cells of a mesh fitted all at once (cells missing here and there): one sparse LU of an
#: (m x m) matrix with as many entries per row as a cell has neighbours.
MAX_ALL_CELLS = 20000

#: Most cells listed by name in a finding; the rest are counted.
_LISTED = 8

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


def stiffest_cells(split: ElementSplit, k: int) -> List[int]:
    """The k cells (ids) with the largest norm of the oracle's element matrix per rest volume:
    where an error that grows steeply with the state (a stiff exponential's) is largest.
    """
    m = split.cells.shape[0]
    density = np.linalg.norm(split.Ke.reshape(m, -1), axis=1) / np.abs(split.V0)
    return [int(i) for i in np.argsort(-density)[:k]]


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


def fit_all_cells(
    cells: np.ndarray,
    n: int,
    fe: np.ndarray,
    Ke: np.ndarray,
    df: np.ndarray,
    dK: sp.spmatrix,
    s: Scales,
) -> Optional[CellFit]:
    """:func:`fit_cell_contributions` over every cell at once, for an error spread over the
    mesh: the normal equations of the sparse design matrix (one column a cell: its 12 force and
    144 matrix entries, weighted by the case's scales), solved by sparse LU. None beyond
    :data:`MAX_ALL_CELLS` cells or when the equations are singular (no unique reading).
    """
    from scipy.sparse.linalg import spsolve

    m = cells.shape[0]
    if m > MAX_ALL_CELLS:
        return None
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    key = (np.repeat(dof, 12, axis=1) * (3 * n) + np.tile(dof, (1, 12))).ravel()
    keys, row = np.unique(key, return_inverse=True)  # the matrix entries cells touch
    A_f = sp.csc_matrix(
        (fe.reshape(-1) / s.force, (dof.ravel(), np.repeat(np.arange(m), 12))), shape=(3 * n, m)
    )
    A_K = sp.csc_matrix(
        (Ke.reshape(-1) / s.stiffness, (row, np.repeat(np.arange(m), 144))),
        shape=(keys.size, m),
    )
    D = sp.csr_matrix(dK)
    b_K = np.asarray(D[keys // (3 * n), keys % (3 * n)]).ravel() / s.stiffness
    b_f = np.asarray(df).ravel() / s.force
    G = (A_f.T @ A_f + A_K.T @ A_K).tocsc()
    with np.errstate(all="ignore"):
        alpha = np.atleast_1d(spsolve(G, A_f.T @ b_f + A_K.T @ b_K))
    if not np.all(np.isfinite(alpha)):
        return None
    f_fit, K_fit = assemble(cells, n, alpha[:, None, None] * fe, alpha[:, None, None] * Ke)
    e = errors(f_fit, K_fit, None, np.asarray(df), D, 0.0, s)
    return CellFit(np.arange(m), alpha, e.force, e.stiffness)


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
    if len(out) > _LISTED:
        out = out[:_LISTED] + [f"and {len(out) - _LISTED} more cells"]
    return out


def _finding(fit: CellFit, residual: float) -> Optional[Finding]:
    """The finding for the cells whose coefficient is not zero (None: no such cell)."""
    keep = np.abs(fit.alpha) > _INTEGER
    words = _describe(fit)
    if not words:
        return None
    listed = [(int(c), float(a)) for c, a in zip(fit.cells[keep], fit.alpha[keep])]
    combo = " + ".join(f"{a:+.6g} x [cell {c}]" for c, a in listed[:_LISTED])
    return Finding(
        "cell-contribution",
        "; ".join(words),
        FULL,
        f"engine - oracle is {combo}{' + ...' if len(listed) > _LISTED else ''} (those cells' "
        f"element force and matrix, MJED's, whose sum is the oracle's to {residual:.1e}): left "
        f"force error {fit.force:.1e}, stiffness error {fit.stiffness:.1e}",
        {
            "cells": [c for c, _ in listed],
            "coefficients": [a for _, a in listed],
            "residual": max(fit.force, fit.stiffness),
        },
    )


def _split_and_difference(diag, ci, out, ref, s: Scales):
    """(MJED's split of the oracle, engine - oracle force, stiffness), or None without a split."""
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, diag.tolerances
    )
    if split is None:
        return None
    df = np.asarray(out.force) - ref.force
    return split, df, sp.csr_matrix(out.stiffness) - ref.stiffness


def cell_contribution_reading(diag, ci, out, ref, s: Scales):
    """``diag`` whose first cause is an error localised to a few cells, with the cells named
    when the error is their contributions missing or repeated (the localisation kept as an
    observation); unchanged otherwise (no MJED split, or the fit does not agree).
    """
    lead = diag.causes[0] if diag.causes else None
    if lead is None or lead.code != "localised" or not lead.figures.get("cells"):
        return diag
    tol: Tolerances = diag.tolerances
    got = _split_and_difference(diag, ci, out, ref, s)
    if got is None:
        return diag
    split, df, dK = got
    fit = fit_cell_contributions(
        split.cells, split.n, split.fe, split.Ke, df, dK, np.asarray(lead.figures["cells"]), s
    )
    if fit is None or fit.force > tol.force or fit.stiffness > tol.stiffness:
        return diag
    finding = _finding(fit, split.residual)
    if finding is None:
        return diag
    rest = [replace(f, strength=OBSERVED) if f is lead else f for f in diag.findings]
    return replace(diag, findings=[finding, *rest])


def spread_cells_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained) with the cells named when the error is some
    cells' contributions missing or repeated anywhere in the mesh (:func:`fit_all_cells`);
    named only for fewer than half of the cells (more is a mistake of every cell, which the
    other readings name); unchanged otherwise.
    """
    tol: Tolerances = diag.tolerances
    if ci.cells.shape[0] > MAX_ALL_CELLS:
        return diag
    got = _split_and_difference(diag, ci, out, ref, s)
    if got is None:
        return diag
    split, df, dK = got
    fit = fit_all_cells(split.cells, split.n, split.fe, split.Ke, df, dK, s)
    if fit is None or fit.force > tol.force or fit.stiffness > tol.stiffness:
        return diag
    if 2 * np.count_nonzero(np.abs(fit.alpha) > _INTEGER) > fit.alpha.size:
        return diag
    finding = _finding(fit, split.residual)
    if finding is None:
        return diag
    return replace(diag, findings=[finding, *(f for f in diag.findings if f.code != "unexplained")])
