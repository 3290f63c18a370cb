"""Stiffness stored with some 3x3 node blocks transposed.

An engine that stores K by node pairs (the paper's per-edge blocks K_ij, a block-CSR, a COO
of 3x3 blocks) writes block (i, j) and must write block (j, i) as its transpose. Written
untransposed (K_ij at (j, i)), K loses its symmetry in a way no formula mistake has: the
error lives on the off-diagonal blocks of one triangle only, and it is exactly
``K_ij - K_ij^T`` there. The same happens per cell when a cell's block K_ab is added to the
edge (min, max) without transposing it where the cell walks the edge from its larger node.

Each pattern is tested exactly on the oracle's K: its blocks transposed where the pattern says
(global: below the diagonal, above it, all off-diagonal blocks; per cell, from the oracle's
element matrices: the blocks of the cells walking an edge against, or along, the global node
order) and compared with the engine's K. NumPy only.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, element_split
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "GLOBAL_PATTERNS",
    "CELL_PATTERNS",
    "DIAGONAL",
    "transpose_global_blocks",
    "transpose_cell_blocks",
    "mirror_node_blocks",
    "transposed_findings",
    "transposed_blocks_reading",
]

#: Global patterns: name -> words (which blocks (i, j) of K, i and j node numbers, are stored
#: transposed).
GLOBAL_PATTERNS: Dict[str, str] = {
    "lower": "the blocks below the diagonal (node i > node j) stored untransposed: K_ij "
    "written at (j, i) instead of K_ij^T, K's lower triangle not the transpose of its upper",
    "upper": "the blocks above the diagonal (node i < node j) stored untransposed: K_ji "
    "written at (i, j) instead of K_ji^T, K's upper triangle not the transpose of its lower",
    "all": "every off-diagonal 3x3 block stored transposed (K_ij^T at (i, j))",
}

#: Per-cell patterns: name -> words.
CELL_PATTERNS: Dict[str, str] = {
    "against": "a cell's off-diagonal blocks K_ab added to the edge untransposed where the cell "
    "walks the edge from its larger node (global a > b): those edge blocks transposed, an "
    "edge-orientation mistake of per-edge storage",
    "along": "a cell's off-diagonal blocks K_ab added to the edge transposed where the cell "
    "walks the edge from its smaller node (global a < b): those edge blocks transposed, an "
    "edge-orientation mistake of per-edge storage",
}


#: Symmetric storage from one triangle: pattern -> words (the diagonal entries of K alone).
DIAGONAL: Dict[str, str] = {
    "doubled": "symmetric storage mirrored with its diagonal: K = U + U^T with U the upper (or "
    "lower) triangle including the diagonal, so every diagonal entry of K is doubled, the "
    "off-diagonal entries right",
    "dropped": "symmetric storage mirrored without its diagonal: K = U + U^T with U the strict "
    "upper (or lower) triangle, so every diagonal entry of K is missing",
}


def transpose_global_blocks(K: sp.spmatrix, pattern: str) -> sp.csr_matrix:
    """K (3n, 3n) with its 3x3 node blocks (i, j) transposed where ``pattern`` says: "lower"
    (i > j), "upper" (i < j) or "all" (i != j).
    """
    C = sp.coo_matrix(K)
    bi, bj = C.row // 3, C.col // 3
    pick = {"lower": bi > bj, "upper": bi < bj, "all": bi != bj}[pattern]
    # Entry (3i + r, 3j + c) of a transposed block holds the block's (c, r) entry.
    rows = np.where(pick, 3 * bi + C.col % 3, C.row)
    cols = np.where(pick, 3 * bj + C.row % 3, C.col)
    return sp.csr_matrix((C.data, (rows, cols)), shape=K.shape)


def mirror_node_blocks(K: sp.spmatrix) -> sp.csr_matrix:
    """K (3n, 3n) with each node block (i, i) written twice, as itself and again transposed at
    (i, i): the edges' mirror rule (K_ij at (i, j), K_ij^T at (j, i)) applied to the nodes.
    """
    C = sp.coo_matrix(K)
    node = C.row // 3 == C.col // 3
    # The transposed copy of a node block: entry (3i + r, 3i + c) gets the block's (c, r).
    rows = 3 * (C.row[node] // 3) + C.col[node] % 3
    cols = 3 * (C.col[node] // 3) + C.row[node] % 3
    extra = sp.csr_matrix((C.data[node], (rows, cols)), shape=K.shape)
    return (sp.csr_matrix(K) + extra).tocsr()


def transpose_cell_blocks(split: ElementSplit, pattern: str) -> sp.csr_matrix:
    """The oracle's element matrices (m, 12, 12) assembled with the off-diagonal blocks (a, b)
    of each cell transposed where the cell's local order of the pair runs "against" the global
    node order (local a < b, global node a > node b) or "along" it.
    """
    m = split.cells.shape[0]
    Ke = split.Ke.reshape(m, 4, 3, 4, 3)
    a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")  # (4, 4) local pairs
    ga, gb = split.cells[:, a], split.cells[:, b]  # (m, 4, 4) their global nodes
    # The pair {a, b} is walked from the local first: against the global order when the
    # local first has the larger global number. Both (a, b) and (b, a) blocks follow the pair.
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    against = split.cells[:, lo] > split.cells[:, hi]
    pick = (against if pattern == "against" else ~against) & (ga != gb)
    Kt = np.swapaxes(Ke, 2, 4)  # each (a, b) block transposed in place
    Kp = np.where(pick[:, :, None, :, None], Kt, Ke)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Kp.reshape(m, 12, 12))[1]


def transposed_findings(
    K: sp.spmatrix,
    K_o: sp.spmatrix,
    f: np.ndarray,
    f_o: np.ndarray,
    s: Scales,
    tol: Tolerances,
    split: Optional[ElementSplit] = None,
) -> List[Finding]:
    """The patterns whose transposed oracle K matches the engine's K (3n, 3n) within ``tol``,
    the force f (n, 3) matching too; several matching are said as ambiguous.
    """
    K = sp.csr_matrix(K)
    K_o = sp.csr_matrix(K_o)
    if not tol.within(errors(f, K_o, None, f_o, K_o, 0.0, s), energy=False):
        return []  # the force is wrong: storing K does not touch it
    if tol.within(errors(f, K, None, f_o, K_o, 0.0, s), energy=False):
        return []
    candidates = [
        (f"global-{p}", words, transpose_global_blocks(K_o, p))
        for p, words in GLOBAL_PATTERNS.items()
    ]
    candidates.append(
        (
            "node-mirror",
            "the node (diagonal) blocks K_ii written with the edges' mirror rule: at (i, i) and "
            "again transposed at (i, i), each node block doubled",
            mirror_node_blocks(K_o),
        )
    )
    # Symmetric storage of one triangle: K = U + U^T with U's diagonal kept doubles every
    # diagonal entry; with U strictly upper it loses them. Both touch the diagonal alone.
    diag = sp.diags(K_o.diagonal())
    candidates += [
        ("diagonal-doubled", DIAGONAL["doubled"], (K_o + diag).tocsr()),
        ("diagonal-dropped", DIAGONAL["dropped"], (K_o - diag).tocsr()),
    ]
    if split is not None:
        candidates += [
            (f"cell-{p}", words, transpose_cell_blocks(split, p))
            for p, words in CELL_PATTERNS.items()
        ]
    before = errors(f, K, None, f_o, K_o, 0.0, s).stiffness
    found = []
    for name, words, Kp in candidates:
        if float(abs(Kp - K_o).max()) == 0.0:
            continue  # no block changes on this case: no evidence either way
        e = errors(f, K, None, f_o, Kp, 0.0, s)
        if not tol.within(e, energy=False):
            continue
        on_diagonal = name.startswith("diagonal")
        where = "its diagonal entries" if on_diagonal else "those 3x3 blocks"
        found.append(
            Finding(
                "storage-diagonal" if on_diagonal else "storage-transposed-blocks",
                "stiffness storage: " + words,
                FULL,
                f"the oracle's K with {where} so written matches the engine's K to "
                f"{e.stiffness:.1e} (against {before:.1e} as the oracle's); the force matches; "
                f"its error is confined to {where}, not noise",
                {"pattern": name, "stiffness_error": e.stiffness, "before": before},
            )
        )
    return ambiguous(found, "the transposed blocks coincide on this case")


def transposed_blocks_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with transposed stiffness blocks named
    first when the engine's K is the oracle's so stored; unchanged otherwise.
    """
    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    found = transposed_findings(out.stiffness, ref.stiffness, out.force, ref.force, s, tol, split)
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
