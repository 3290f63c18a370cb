"""Assembly that adds a repeated entry once: buffered fancy indexing.

``force[dofs] -= fe`` or ``K[rows, cols] += Ke`` with NumPy arrays reads every indexed entry
once, adds, and writes back: where an index repeats (a node shared by several cells, a matrix
entry two cells touch), the writes overwrite each other and the entry keeps one cell's
contribution, not their sum (``np.add.at``, a COO sum or a loop accumulate). In practice the
last write wins, so the entry holds the last cell's contribution in the order the cells are
indexed; an engine looping the other way would keep the first cell's. The same happens to a
hand-built CSR or dense matrix filled by ``data[position] += values``.

The hypothesis is tested exactly on the oracle's element forces and matrices (MJED's, used only
where their sum is the oracle's: :func:`conformance.diagnosis.elements.element_split`): each
force and stiffness entry given the contribution of one cell (the last, or the first, that
touches it) and compared with the engine. Force and stiffness are read separately (an engine
may accumulate one correctly and not the other). NumPy only: no oracle form is compiled.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, element_split
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "RULES",
    "kept_occurrence",
    "buffered_force",
    "buffered_stiffness",
    "buffered_findings",
    "buffered_assembly_reading",
]

#: How a repeated entry is written: "sum" (accumulated, right), "last" or "first" (one cell's
#: contribution kept: the last or the first in the order the cells are indexed), "one" (one
#: cell's contribution kept, whichever the engine's own write order left: entry by entry, the
#: contribution that equals the engine's value; tried where neither "last" nor "first" fits).
RULES = ("sum", "last", "first")

_WHOSE = {
    "last": "the last cell's in the mesh's cell order",
    "first": "the first cell's in the mesh's cell order: a buffered write looping the cells "
    "backwards, or one that skips an entry already set",
    "one": "one of its cells', in your engine's own write order (e.g. triplets listed block by "
    "block, then an assignment or a de-duplication that keeps one of each)",
}


def kept_occurrence(keys: np.ndarray, rule: str) -> Tuple[np.ndarray, np.ndarray]:
    """(unique keys (u,), index into ``keys`` (N,) of the occurrence each keeps): the last or
    the first occurrence of each key. Deterministic (not NumPy's own unspecified write order).
    """
    if rule == "first":
        uniq, idx = np.unique(keys, return_index=True)
        return uniq, idx
    uniq, idx = np.unique(keys[::-1], return_index=True)
    return uniq, keys.size - 1 - idx


def kept_by_engine(
    keys: np.ndarray, values: np.ndarray, engine: np.ndarray, atol: float
) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """(unique keys (u,), the value each keeps) where every key's engine value (``engine``
    (N,), the engine's entry at each occurrence's key) equals one of its occurrences' values
    (N,) to ``atol``; None if some key has none that does.
    """
    hit = np.abs(engine - values) <= atol
    order = np.lexsort((~hit, keys))  # per key, an occurrence that matches first
    uniq, start = np.unique(keys[order], return_index=True)
    first = order[start]
    if not hit[first].all():
        return None
    return uniq, values[first]


def one_cell_force(cells: np.ndarray, fe: np.ndarray, f: np.ndarray, atol: float):
    """The element forces fe (m, 4, 3) assembled keeping, per dof, the one cell's contribution
    that the engine's f (n, 3) holds (:func:`kept_by_engine`); None where some dof holds none.
    """
    keys = _dofs(cells).ravel()
    kept = kept_by_engine(keys, fe.reshape(-1), np.asarray(f, float).ravel()[keys], atol)
    if kept is None:
        return None
    out = np.zeros(f.size)
    out[kept[0]] = kept[1]
    return out.reshape(f.shape)


def one_cell_stiffness(cells: np.ndarray, n: int, Ke: np.ndarray, K: sp.csr_matrix, atol: float):
    """The element matrices Ke (m, 12, 12) assembled keeping, per entry, the one cell's
    contribution that the engine's K (3n, 3n) holds; None where some entry holds none.
    """
    dof = _dofs(cells)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    engine = np.asarray(K[rows, cols]).ravel()
    keys = rows.astype(np.int64) * (3 * n) + cols
    kept = kept_by_engine(keys, Ke.reshape(-1), engine, atol)
    if kept is None:
        return None
    uniq, vals = kept
    return sp.csr_matrix((vals, (uniq // (3 * n), uniq % (3 * n))), shape=(3 * n, 3 * n))


def _dofs(cells: np.ndarray) -> np.ndarray:
    """(m, 12) global dofs of each cell, node-major (3 node + component)."""
    m = cells.shape[0]
    return (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)


def buffered_force(cells: np.ndarray, n: int, fe: np.ndarray, rule: str) -> np.ndarray:
    """Element forces fe (m, 4, 3) assembled to (n, 3) with ``rule`` for repeated dofs."""
    if rule == "sum":
        return assemble(cells, n, fe, None)[0]
    keys = _dofs(cells).ravel()
    uniq, idx = kept_occurrence(keys, rule)
    f = np.zeros(3 * n)
    f[uniq] = fe.reshape(-1)[idx]
    return f.reshape(n, 3)


def buffered_stiffness(cells: np.ndarray, n: int, Ke: np.ndarray, rule: str) -> sp.csr_matrix:
    """Element matrices Ke (m, 12, 12) assembled to (3n, 3n) with ``rule`` for repeated
    entries (within one cell every (row, column) pair is distinct, so only cells compete).
    """
    m = cells.shape[0]
    dof = _dofs(cells)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    if rule == "sum":
        return sp.csr_matrix((Ke.reshape(-1), (rows, cols)), shape=(3 * n, 3 * n))
    keys = rows.astype(np.int64) * (3 * n) + cols
    uniq, idx = kept_occurrence(keys, rule)
    vals = Ke.reshape(m * 144)[idx]
    return sp.csr_matrix((vals, (uniq // (3 * n), uniq % (3 * n))), shape=(3 * n, 3 * n))


def _words(rule_f: str, rule_K: str) -> str:
    """The finding's title for force and stiffness assembled by these rules."""
    parts = [
        f"each {what} entry shared by several cells holds one cell's contribution "
        f"({_WHOSE[rule]}), not their sum"
        for what, rule in (("force", rule_f), ("stiffness", rule_K))
        if rule != "sum"
    ]
    which = " and ".join(w for w, r in (("force", rule_f), ("stiffness", rule_K)) if r != "sum")
    return (
        f"{which} assembled adding each repeated entry once: "
        + "; ".join(parts)
        + ". NumPy's buffered fancy indexing (`force[dofs] -= fe`, `K[rows, cols] += Ke`) "
        "writes a repeated index once, where np.add.at or a COO sum accumulates"
    )


def buffered_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The assembly rules (force, stiffness) other than (sum, sum) whose result matches the
    engine's f (n, 3) and K (3n, 3n); several matching are said as ambiguous.
    """
    K = sp.csr_matrix(K)
    forces = {r: buffered_force(split.cells, split.n, split.fe, r) for r in RULES}
    stiffnesses = {r: buffered_stiffness(split.cells, split.n, split.Ke, r) for r in RULES}
    found = _matching(split, f, K, s, tol, forces, stiffnesses)
    if found:
        return ambiguous(found)
    # Neither the mesh's order nor its reverse: the engine's own order, read entry by entry.
    one_f = one_cell_force(split.cells, split.fe, f, tol.force * s.force)
    one_K = one_cell_stiffness(split.cells, split.n, split.Ke, K, tol.stiffness * s.stiffness)
    if one_f is not None:
        forces = {"sum": forces["sum"], "one": one_f}
    if one_K is not None:
        stiffnesses = {"sum": stiffnesses["sum"], "one": one_K}
    if one_f is None and one_K is None:
        return []
    return ambiguous(_matching(split, f, K, s, tol, forces, stiffnesses))


def _matching(split, f, K, s, tol, forces, stiffnesses) -> List[Finding]:
    """The findings of the (force, stiffness) rules, not both "sum", whose assembly matches."""
    found = []
    for rf, rK in itertools.product(forces, stiffnesses):
        if rf == rK == "sum":
            continue
        e = errors(f, K, None, forces[rf], stiffnesses[rK], 0.0, s)
        if not tol.within(e, energy=False):
            continue
        found.append(
            Finding(
                "assembly-repeated-once",
                _words(rf, rK),
                FULL,
                "the oracle's element forces and matrices (MJED's, whose sum is the oracle's to "
                f"{split.residual:.1e}) assembled so: force error {e.force:.1e}, stiffness error "
                f"{e.stiffness:.1e}",
                {"force_rule": rf, "stiffness_rule": rK, "residual": max(e.force, e.stiffness)},
            )
        )
    return found


def buffered_assembly_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the buffered assembly named first
    when the engine's output is it; unchanged otherwise (or when MJED does not split the case).
    """
    tol = diag.tolerances
    split: Optional[ElementSplit] = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    found = buffered_findings(split, out.force, out.stiffness, s, tol)
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
