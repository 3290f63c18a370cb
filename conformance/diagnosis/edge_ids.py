"""An edge-based engine's table of edge ids read in the other layout.

An engine that stores K per mesh edge (SOFA-style: a 3x3 block per edge, the reverse direction
its transpose, and one per vertex) maps each cell's six node pairs to edge ids once, in a table
of m x 6 ids. Built in one layout (pair-major: the six pairs' columns one after the other, as a
loop over the pairs with a vectorised search over the cells writes it) and read in the other
(``reshape(m, 6)``, cell-major), every cell's pair block lands on the edge of another cell's
pair; the blocks themselves (and the vertex blocks, and the force) are right. The reverse slip
(built cell-major, read pair-major) is the inverse permutation.

Tested exactly on the oracle's element matrices (MJED's, used only where their sum is the
oracle's: :func:`conformance.diagnosis.elements.element_split`): the pairs in the usual order
(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), each block oriented from the cell's smaller
global node to its larger (transposed where the cell walks the edge the other way), added to
the edge the slipped table names, and written with its transpose. NumPy and SciPy only.
"""

from __future__ import annotations

from typing import List

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, element_split
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, ambiguous, named_first
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["PAIRS", "SLIPS", "slipped_stiffness", "edge_id_findings", "edge_id_reading"]

#: The six node pairs of a cell, in the order the table's columns hold them.
PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))

#: slip -> words.
SLIPS = {
    "pair-major-read-as-cell-major": "the table of each cell's six edge ids built pair-major (the "
    "six pairs' columns one after the other) and read cell-major (reshape(m, 6)): each cell's "
    "pair blocks added to other cells' edges",
    "cell-major-read-as-pair-major": "the table of each cell's six edge ids built cell-major and "
    "read pair-major (reshape(6, m)): each cell's pair blocks added to other cells' edges",
}


def _node_blocks(rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray, n: int) -> sp.csr_matrix:
    """(3n, 3n) the 3x3 ``blocks`` (..., 3, 3) summed at node rows and columns (...,)."""
    comp = np.arange(3)
    r = np.broadcast_to(3 * rows[..., None, None] + comp[:, None], blocks.shape)
    c = np.broadcast_to(3 * cols[..., None, None] + comp[None, :], blocks.shape)
    return sp.csr_matrix((blocks.ravel(), (r.ravel(), c.ravel())), shape=(3 * n, 3 * n))


def slipped_stiffness(split: ElementSplit, slip: str) -> sp.csr_matrix:
    """K (3n, 3n) from the split's element matrices, the edge blocks added at the edges the
    table names when read with ``slip`` (a key of :data:`SLIPS`, or "none": read as written);
    the vertex blocks right.
    """
    cells, n = split.cells, split.n
    m = cells.shape[0]
    Kb = split.Ke.reshape(m, 4, 3, 4, 3)
    a = np.array([p[0] for p in PAIRS])
    b = np.array([p[1] for p in PAIRS])
    block = Kb[:, a, :, b, :]  # (6, m, 3, 3): rows of node a, columns of node b
    block = np.swapaxes(block, 0, 1)  # (m, 6, 3, 3)
    flip = cells[:, a] > cells[:, b]  # (m, 6): store as (smaller node, larger node)
    block = np.where(flip[..., None, None], np.swapaxes(block, -1, -2), block)
    lo = np.minimum(cells[:, a], cells[:, b])
    hi = np.maximum(cells[:, a], cells[:, b])
    # The slot (c, p) of the table as read holds the id written for (c', p').
    c, p = np.meshgrid(np.arange(m), np.arange(6), indexing="ij")
    if slip == "none":  # the table read as written: the right assembly
        cs, ps = c, p
    elif slip == "pair-major-read-as-cell-major":
        flat = 6 * c + p  # read cell-major from a pair-major buffer: flat = p' m + c'
        cs, ps = flat % m, flat // m
    elif slip == "cell-major-read-as-pair-major":
        flat = p * m + c  # read pair-major from a cell-major buffer: flat = 6 c' + p'
        cs, ps = flat // 6, flat % 6
    else:
        raise ValueError(f"unknown slip {slip!r}")
    off = _node_blocks(lo[cs, ps], hi[cs, ps], block, n)
    vertex = np.swapaxes(Kb[:, np.arange(4), :, np.arange(4), :], 0, 1)  # (m, 4, 3, 3)
    V = _node_blocks(cells, cells, vertex, n)
    return (V + off + off.T).tocsr()


def edge_id_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The slips of :data:`SLIPS` whose stiffness matches the engine's (and not the oracle's)."""
    K = sp.csr_matrix(K)
    f0 = np.zeros((split.n, 3))
    np.add.at(f0, split.cells, split.fe)
    right = slipped_stiffness(split, "none")
    found = []
    for slip, words in SLIPS.items():
        Kh = slipped_stiffness(split, slip)
        if errors(f0, Kh, None, f0, right, 0.0, s).stiffness <= tol.stiffness:
            continue  # the slip moves nothing on this mesh
        e = errors(f, K, None, f0, Kh, 0.0, s)
        if e.stiffness > tol.stiffness:
            continue
        force_right = e.force <= tol.force
        found.append(
            Finding(
                "edge-ids-" + slip,
                words,
                FULL if force_right else PARTIAL,
                f"the oracle's element matrices added to the edges that table names: stiffness "
                f"error {e.stiffness:.1e}"
                + ("; the force matches" if force_right else "; the force is wrong besides"),
                {"stiffness_error": e.stiffness},
            )
        )
    return ambiguous(found)


def edge_id_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with a slipped edge-id table named first
    when the engine's stiffness is it; unchanged otherwise.
    """
    tol = diag.tolerances
    if out.stiffness is None or diag.errors.stiffness <= tol.stiffness:
        return diag
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    return named_first(diag, edge_id_findings(split, out.force, out.stiffness, s, tol))
