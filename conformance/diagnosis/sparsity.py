"""Stiffness entries where the mesh has none: the indices of the stored stiffness are wrong.

A P1 element couples only the four nodes of its cell, so every assembled stiffness (the
oracle's, an engine's whatever its formula, a finite-difference one, global or per element:
perturbing a dof changes only the forces of the cells around its node) is zero on the node
pairs that share no cell. An error there is not a formula's, a tangent's or an approximation's:
the engine wrote values at wrong rows or columns (COO indices built wrongly, a scatter with the
wrong map, a dof numbering not undone). How much of the error lies there is a measurement, and
no prediction of the engine's output is claimed: the reading partly explains.

NumPy and SciPy only.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import PARTIAL, Finding

__all__ = ["OFF_PATTERN", "node_pairs", "off_pattern_fraction", "off_pattern_reading"]

#: The error is read as misplaced when more than this fraction of its norm lies off the mesh's
#: pattern (exactly zero for any assembly of element matrices, whatever their values).
OFF_PATTERN = 1e-6


def node_pairs(cells: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """(n, n) boolean pattern: True where nodes i and j share a cell (i == j included).
    cells (m, 4) node indices.
    """
    cells = np.asarray(cells)
    rows = np.repeat(cells, cells.shape[1], axis=1).ravel()
    cols = np.tile(cells, (1, cells.shape[1])).ravel()
    pattern = sp.csr_matrix((np.ones(rows.size, dtype=bool), (rows, cols)), (n_nodes, n_nodes))
    pattern.sum_duplicates()
    return pattern


def _off_pattern(cells: np.ndarray, D: sp.spmatrix) -> "tuple[float, int]":
    """(fraction of the norm of the stiffness error ``D`` (3n, 3n) on node pairs sharing no
    cell, how many nonzero entries lie there); the fraction is NaN for D = 0.
    """
    C = sp.coo_matrix(D)
    total = float(np.linalg.norm(C.data))
    if total == 0.0:
        return float("nan"), 0
    pattern = node_pairs(cells, D.shape[0] // 3)
    outside = ~np.asarray(pattern[C.row // 3, C.col // 3]).ravel()
    return float(np.linalg.norm(C.data[outside])) / total, int(np.count_nonzero(C.data[outside]))


def off_pattern_fraction(cells: np.ndarray, D: sp.spmatrix) -> float:
    """Fraction of the norm of the stiffness error ``D`` (3n, 3n) on node pairs sharing no
    cell; 0 for an error that any element assembly could make, NaN for D = 0.
    """
    return _off_pattern(cells, D)[0]


def off_pattern_reading(diag, ci, out, ref, s):
    """``diag`` led by the misplaced-entries finding when the stiffness error lies partly off the
    mesh's pattern; unchanged otherwise (no stiffness, or an error every assembly could make).
    """
    if out.stiffness is None or ref.stiffness is None:
        return diag
    D = (sp.csr_matrix(out.stiffness) - sp.csr_matrix(ref.stiffness)).tocsr()
    fraction, entries = _off_pattern(ci.cells, D)
    if not np.isfinite(fraction) or fraction <= OFF_PATTERN:
        return diag
    finding = Finding(
        "misplaced-stiffness-entries",
        "stiffness entries where the mesh has none: the row or column indices of your stored "
        "stiffness (or the map that scatters element matrices) are wrong",
        PARTIAL,
        f"{100 * fraction:.1f} % of the stiffness error (in norm) lies on {entries} "
        "entries coupling nodes that share no cell, where every P1 assembly is zero whatever "
        "its formula (finite differences included); no formula, tangent or approximation "
        "reading can account for them",
        {"off_pattern": fraction, "entries": entries},
    )
    return dataclasses.replace(
        diag, findings=[finding, *(f for f in diag.findings if f.code != "unexplained")]
    )
