"""Element forces written to the wrong local nodes, or with a local node's sign wrong (force only).

An engine that builds each cell's four nodal forces by hand (Sifakis' H = -V0 P Dm^-T gives the
forces on nodes 1, 2, 3; node 0's is minus their sum) may slip inside the cell without touching
its element matrix: the forces stacked in one node order and scattered in another (H's columns
[f1, f2, f3, f0] sent to nodes (0, 1, 2, 3)), or one node's force written with the wrong sign
(f0 = f1 + f2 + f3 where -(f1 + f2 + f3) belongs: the cell's forces then no longer sum to zero).
Its force is then, exactly, the oracle's element forces (MJED's, used only where their sum is
the oracle's: :func:`conformance.diagnosis.elements.element_split`) with local node a given
sign_a f_{p(a)}, for a permutation p of the four local nodes and signs sign_a = +-1, while its
stiffness is the oracle's.

Each of the 24 x 16 maps is assembled (the identity and the global sign flip, which the global
readings name, left out); one is named only when the engine's force matches it and its
stiffness matches the oracle's within the case's tolerance. Several: ambiguous. Nothing is
fitted. The stiffness wrong too (the element matrix reordered alike) is
:func:`conformance.diagnosis.elements.order_findings`'s.
"""

from __future__ import annotations

import itertools
from typing import List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, split_finding
from conformance.diagnosis.findings import Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["BUFFER_SLIPS", "node_maps", "node_map_words", "force_node_findings"]


def node_maps() -> List[Tuple[Tuple[int, ...], Tuple[int, ...]]]:
    """(p, signs) for every map of the four local nodes' forces but the identity and the global
    sign flip: local node a receives signs[a] * f[p[a]].
    """
    out = []
    for p in itertools.permutations(range(4)):
        for signs in itertools.product((1, -1), repeat=4):
            same = p == (0, 1, 2, 3)
            if same and len(set(signs)) == 1:
                continue
            out.append((p, signs))
    return out


def node_map_words(p: Tuple[int, ...], signs: Tuple[int, ...]) -> str:
    """The map (p, signs) in words: which local node's force each node receives and with which
    sign, and what that means (a shift of the node order, the forces no longer summing to zero).
    """
    parts = []
    if p != (0, 1, 2, 3):
        shift = next((k for k in (1, 2, 3) if p == tuple((a + k) % 4 for a in range(4))), None)
        stacked = ", ".join(f"f{b}" for b in p)
        what = (
            f"shifted by {shift} local node{'s' if shift > 1 else ''}"
            if shift is not None
            else f"the cell's nodes taken as {p}"
        )
        parts.append(
            f"element forces scattered to the wrong local nodes (node order {what}): the forces "
            f"stacked as [{stacked}] but scattered to the cell's nodes (0, 1, 2, 3)"
        )
    flipped = [a for a in range(4) if signs[a] < 0]
    if flipped:
        nodes = ", ".join(str(a) for a in flipped)
        one = len(flipped) == 1
        example = ""
        if one and p == (0, 1, 2, 3):
            a = flipped[0]
            rest = " + ".join(f"f{b}" for b in range(4) if b != a)
            example = f" (f{a} = {rest} where -({rest}) belongs)"
        parts.append(
            f"the force on each cell's local node{'' if one else 's'} {nodes} written with the "
            f"wrong sign{example}: the cell's element forces do not sum to zero (a net force "
            "on every cell, not balanced)"
        )
    return "; ".join(parts)


def force_node_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The maps of :func:`node_maps` whose force, assembled from the oracle's element forces
    fe (m, 4, 3), matches the engine's f (n, 3) while the engine's K (3n, 3n) is the oracle's
    (the split's sum); several are said as ambiguous.
    """
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    K = sp.csr_matrix(K)
    if not tol.within(errors(f0, K, None, f0, K0, 0.0, s), energy=False):
        return []  # the stiffness is wrong too: not a force-only slip
    found = []
    for p, signs in node_maps():
        fe = np.asarray(signs, dtype=float)[None, :, None] * split.fe[:, list(p)]
        e = errors(f, K, None, assemble(split.cells, split.n, fe, None)[0], K0, 0.0, s)
        if tol.within(e, energy=False):
            title = f"force only: {node_map_words(p, signs)}; the stiffness is right"
            figures = {
                "order": [int(b) for b in p],
                "signs": [int(x) for x in signs],
                "residual": max(e.force, e.stiffness),
            }
            how = "and forces, the forces mapped"
            found.append(split_finding("element-force-nodes", title, split, how, e, figures))
    for code, words, read_back in BUFFER_SLIPS:
        fe = read_back(split.fe)
        e = errors(f, K, None, assemble(split.cells, split.n, fe, None)[0], K0, 0.0, s)
        if tol.within(e, energy=False):
            title = f"force only: {words}; the stiffness is right"
            how = "and forces, the forces read back so"
            figures = {"residual": max(e.force, e.stiffness)}
            found.append(split_finding(code, title, split, how, e, figures))
    return ambiguous(found)


def _components_first(fe: np.ndarray) -> np.ndarray:
    """(m, 4, 3) element forces kept as (4, 3, m) (components first, cells last), raveled, and
    read back against a cell-major dof map (m, 12): every value lands on another cell's dof.
    """
    m = fe.shape[0]
    return np.transpose(fe, (1, 2, 0)).ravel().reshape(m, 4, 3)


def _cells_then_components(fe: np.ndarray) -> np.ndarray:
    """(m, 4, 3) element forces kept cell-major, raveled, and read back as (4, 3, m)."""
    m = fe.shape[0]
    return np.transpose(fe.ravel().reshape(4, 3, m), (2, 0, 1))


#: (code, words, fe (m, 4, 3) -> what the engine scatters): the element forces raveled in one
#: layout against a dof map raveled in another.
BUFFER_SLIPS = (
    (
        "element-force-layout",
        "the element forces kept components first and cells last, (4, 3, m), and raveled "
        "against a cell-major (m, 12) dof map (np.bincount or np.add.at over both raveled): "
        "each value added to another cell's or node's dof",
        _components_first,
    ),
    (
        "element-force-layout",
        "the element forces kept cell-major, (m, 4, 3), and raveled against a dof map kept "
        "components first, (4, 3, m): each value added to another cell's or node's dof",
        _cells_then_components,
    ),
)
