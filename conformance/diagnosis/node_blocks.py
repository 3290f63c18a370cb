"""The stiffness's vertex blocks and edge blocks each scaled by a factor of its own.

An engine that stores K by vertices and edges (SOFA's per-edge blocks, the paper's own layout)
accumulates a 3x3 block per vertex (K_aa) and one per edge (K_ab, a != b), then writes the edge
block and its transpose. Slips in that bookkeeping scale one kind of block and not the other:
each cell's pair visited in both orientations adds every edge block twice; an edge list that
holds each edge once per orientation writes it twice; the vertex loop run once per cell *and*
once per vertex doubles the vertex blocks; a loop over a < b that never reaches the vertex
blocks leaves them out. The engine's K is then alpha K_vertex + beta K_edge of the oracle's own
blocks, which two coefficients fitted by least squares find exactly; named when the fit leaves
the engine within the stiffness tolerance and the factors differ (equal factors are a global
scale, which the global readings name). NumPy and SciPy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, PARTIAL, Finding, named_first
from conformance.judge.compare import Scales, Tolerances

__all__ = ["NodeBlockFit", "split_node_blocks", "fit_node_blocks", "node_block_reading"]


@dataclass(frozen=True)
class NodeBlockFit:
    """K ~ alpha K_vertex + beta K_edge; residual ||K - fit|| / ||K_o||."""

    alpha: float
    beta: float
    residual: float


def split_node_blocks(K: sp.spmatrix) -> tuple:
    """(K_vertex, K_edge): K's 3x3 blocks on the node diagonal (i == j) and off it."""
    C = sp.coo_matrix(K)
    on = C.row // 3 == C.col // 3
    vertex = sp.csr_matrix((C.data[on], (C.row[on], C.col[on])), shape=K.shape)
    edge = sp.csr_matrix((C.data[~on], (C.row[~on], C.col[~on])), shape=K.shape)
    return vertex, edge


def fit_node_blocks(K: sp.spmatrix, K_o: sp.spmatrix) -> Optional[NodeBlockFit]:
    """The two factors that bring the oracle's vertex and edge blocks nearest the engine's K
    (least squares over all entries); None when either kind of block is zero.
    """
    K = sp.csr_matrix(K, dtype=np.float64)
    vertex, edge = split_node_blocks(sp.csr_matrix(K_o, dtype=np.float64))
    nv, ne = sp.linalg.norm(vertex), sp.linalg.norm(edge)
    if nv == 0.0 or ne == 0.0:
        return None
    # The two kinds of blocks sit on disjoint entries: each factor is its own projection.
    alpha = float(vertex.multiply(K).sum()) / nv**2
    beta = float(edge.multiply(K).sum()) / ne**2
    left = K - alpha * vertex - beta * edge
    return NodeBlockFit(alpha, beta, float(sp.linalg.norm(left)) / float(np.hypot(nv, ne)))


def _factor_words(kind: str, a: float) -> str:
    for value, words in (
        (2.0, "doubled (added twice: e.g. a pair visited in both orientations, or listed twice)"),
        (0.0, "left out"),
        (0.5, "halved"),
        (-1.0, "with the wrong sign"),
    ):
        if abs(a - value) <= 1e-6:
            return f"the {kind} blocks {words}"
    return f"the {kind} blocks scaled by {a:.6g}"


def node_block_findings(
    K: sp.spmatrix, K_o: sp.spmatrix, s: Scales, tol: Tolerances, force_right: bool
) -> List[Finding]:
    """The finding when K is the oracle's vertex and edge blocks with factors that differ."""
    fit = fit_node_blocks(K, K_o)
    if fit is None or fit.residual > tol.stiffness:
        return []
    if abs(fit.alpha - fit.beta) <= 1e-6 * max(abs(fit.alpha), abs(fit.beta), 1.0):
        return []  # one global factor: the global readings say it
    wrong = []
    if abs(fit.alpha - 1.0) > 1e-6:
        wrong.append(_factor_words("vertex (diagonal node)", fit.alpha))
    if abs(fit.beta - 1.0) > 1e-6:
        wrong.append(_factor_words("edge (off-diagonal node)", fit.beta))
    return [
        Finding(
            "node-blocks",
            "stiffness assembled with "
            + " and ".join(wrong)
            + ": K = alpha K_vertex + beta K_edge of the oracle's own 3x3 node blocks",
            FULL if force_right else PARTIAL,
            f"alpha = {fit.alpha:.6g} (blocks K_aa), beta = {fit.beta:.6g} (blocks K_ab, "
            f"a != b), fitted by least squares; what is left: {fit.residual:.1e} of the "
            "oracle's K"
            + ("; the force matches" if force_right else "; the force is wrong besides"),
            {"alpha": fit.alpha, "beta": fit.beta, "residual": fit.residual},
        )
    ]


def node_block_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with vertex and edge blocks scaled apart
    named first when they are; unchanged otherwise.
    """
    tol = diag.tolerances
    if out.stiffness is None or diag.errors.stiffness <= tol.stiffness:
        return diag
    found = node_block_findings(
        out.stiffness, ref.stiffness, s, tol, diag.errors.force <= tol.force
    )
    return named_first(diag, found)
