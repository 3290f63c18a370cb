"""The right stiffness values at the wrong entries.

A sparse matrix written as three arrays (CSR's indptr, indices and values; COO's rows, columns
and values) is right only if the values are in the order of their indices. An engine that takes
the indices from one place (a summed and sorted SciPy matrix, a pattern built once) and the
values from another (its own triplets in edge or cell order) writes every value the oracle has,
at entries where they do not belong. No formula mistake does that: the engine's entries, sorted,
are the oracle's entries, sorted, to round-off, while the entries in place are not.

The test is over the union of both matrices' patterns (explicit zeros included), so a value
moved onto an entry the oracle has as zero counts too. Its scope is then read: within each row
(the column indices out of order with the values of the row) or across rows. The specific
storage readings (3x3 blocks transposed, entries written once and not summed) come first: they
are permutations too, and name the pattern. NumPy and SciPy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, PARTIAL, Finding, named_first
from conformance.judge.compare import Scales, Tolerances

__all__ = ["Permutation", "permuted_values", "permuted_values_reading"]


@dataclass(frozen=True)
class Permutation:
    """How the engine's K is the oracle's with its values moved.

    gap: ||sort(K) - sort(K_o)|| / ||K_o|| over the union of both patterns (0 for a pure
    permutation); moved: fraction of those entries whose value differs in place from the
    oracle's by more than the tolerance; entries: how many entries the union holds;
    within_rows: True when each row's values, sorted, are the oracle's row, sorted (only the
    column indices out of order), False when values moved across rows too.
    """

    gap: float
    moved: float
    entries: int
    within_rows: bool


def _union_values(K: sp.csr_matrix, K_o: sp.csr_matrix):
    """(rows, k, k_o): the union pattern's row numbers and both matrices' values there."""
    pattern = (abs(K) + abs(K_o)).tocoo()
    pattern.sum_duplicates()
    rows, cols = pattern.row, pattern.col
    k = np.asarray(K[rows, cols]).ravel()
    k_o = np.asarray(K_o[rows, cols]).ravel()
    return rows, k, k_o


def _sorted_within_rows(rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` sorted within each row (rows kept in their order): lexsort by (value, row)."""
    return values[np.lexsort((values, rows))]


def permuted_values(K: sp.spmatrix, K_o: sp.spmatrix, tol: Tolerances) -> Optional[Permutation]:
    """The permutation reading of the engine's ``K`` (3n, 3n) against the oracle's ``K_o``; None
    when K's values, sorted, are not the oracle's (gap above the stiffness tolerance), when no
    entry is out of place, or when ``K_o`` is zero.
    """
    K = sp.csr_matrix(K, dtype=np.float64)
    K_o = sp.csr_matrix(K_o, dtype=np.float64)
    rows, k, k_o = _union_values(K, K_o)
    norm = float(np.linalg.norm(k_o))
    if norm == 0.0 or k.size < 2:
        return None
    gap = float(np.linalg.norm(np.sort(k) - np.sort(k_o))) / norm
    # A value out of place by the check's own measure: its difference above the tolerance of
    # K's scale, not round-off between two engines.
    moved = np.abs(k - k_o) > tol.stiffness * float(np.abs(k_o).max())
    if gap > tol.stiffness or np.count_nonzero(moved) < 2:
        return None
    in_rows = _sorted_within_rows(rows, k) - _sorted_within_rows(rows, k_o)
    within = float(np.linalg.norm(in_rows)) / norm <= tol.stiffness
    return Permutation(gap, float(np.mean(moved)), int(k.size), bool(within))


def _finding(p: Permutation, force_right: bool) -> Finding:
    where = (
        "within each row: every row holds its own values, the column indices out of order with them"
        if p.within_rows
        else "across rows: the values written in another order than their row and column indices"
    )
    return Finding(
        "stiffness-values-permuted",
        "stiffness values at the wrong positions (the right values, permuted "
        + ("within rows" if p.within_rows else "across rows")
        + "): the sparse arrays' values out of order with their indices (CSR or COO values "
        "in assembly order, the indices from a sorted or summed pattern)",
        FULL if force_right else PARTIAL,
        f"sorted, the engine's {p.entries} stiffness entries equal the oracle's to {p.gap:.1e} "
        f"(relative), while {100 * p.moved:.1f} % of them differ in place; moved {where}"
        + ("; the force matches" if force_right else "; the force is wrong besides"),
        {
            "gap": p.gap,
            "moved": p.moved,
            "entries": p.entries,
            "within_rows": p.within_rows,
        },
    )


def permuted_values_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the stiffness values named as
    permuted when they are; unchanged otherwise.
    """
    if out.stiffness is None or diag.errors.stiffness <= diag.tolerances.stiffness:
        return diag
    p = permuted_values(out.stiffness, ref.stiffness, diag.tolerances)
    if p is None:
        return diag
    force_right = diag.errors.force <= diag.tolerances.force
    return named_first(diag, [_finding(p, force_right)])
