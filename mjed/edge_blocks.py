"""Edge-block algebra: the folded aggregates of a state in, the six 3x3 edge blocks out.

With d_a = dJ/dx_a = cof(F) D_a (paper, eqs. 3-4), the Hessian of the folded energy is

    d2W/dx_a dx_b = (D_a . S-bar D_b) Id                        geometric
                 + sum [first: 2 beta (F A D_a)(x)(F A D_b)
                        second: gamma ((F B D_b)(x)(F B D_a) + (D_a . B D_b) F B F^T)]
                 + d_a (x) F S-hat D_b + F S-hat D_a (x) d_b
                 + g2 d_a (x) d_b                               (regularised, section 2.3)
                 + h d2J/dx_a dx_b,   [d2J/dx_a dx_b]_ij = eps_ijq (F (D_a x D_b))_q
                 + sum_exp c e^u du_a (x) du_b                  (regularised too)

Only the six edge blocks (a < b) are formed: K_ba = K_ab^T and, because the energy is
invariant under translation, K_aa = -sum_{b != a} K_ab.

Every contribution is gathered as one of: an outer product u_a (x) v_b (u, v given per node
(3, 4, m), per edge (3, 6, m) or per cell (3, m)), a per-edge scalar times a per-cell matrix,
a per-edge scalar times Id, or the skew term of d2J; the 54 rows (r, c, edge) of the result
are then summed one at a time in a cache-sized slab, reading node vectors in place.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Hashable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from mjed.aggregates import Aggregates, slot_key
from mjed.cellwise import CellState, apply_matrix, edge_dot, is_zero, stress_node_vectors
from mjed.layout import to_component_major
from mjed.sparse import EDGES
from mjed.terms import IDENTITY, TermGroup
from mjed.workspace import Workspace

__all__ = [
    "TangentSlot",
    "tangent_slots",
    "MeshConstants",
    "edge_blocks",
    "edge_blocks_to_element_matrices",
]

_EA, _EB = EDGES[:, 0], EDGES[:, 1]


class TangentSlot:
    """A (kind, matrix) tangent slot shared by all pairs with the same constant matrix.

    Precomputed once per mesh, component-major: M D_a (3, 4, m), the matrix itself per cell
    (3, 3, m) when it varies, and, for the second kind, D_a . M D_b (6, m).
    """

    def __init__(self, kind: str, matrix: np.ndarray, Dt: np.ndarray, index: int):
        self.kind = kind
        self.matrix = matrix
        self.name = f"slot{index}"
        if kind == "spectral":  # eigenprojectors of C: nothing to precompute
            self.identity = False
            return
        self.identity = matrix is IDENTITY or (
            matrix.shape == (3, 3) and np.array_equal(matrix, IDENTITY)
        )
        self.M_t = None if matrix.ndim == 2 else to_component_major(matrix)
        if self.identity:
            self.MD = Dt
        elif matrix.ndim == 2:
            self.MD = np.einsum("ij,jam->iam", matrix, Dt)
        else:
            self.MD = apply_matrix(self.M_t, Dt)
        if kind == "second":
            self.DMD = edge_dot(Dt, self.MD)

    def FMFt(self, Ft: np.ndarray, ws: Workspace) -> np.ndarray:
        """F M F^T, (3, 3, m)."""
        m = Ft.shape[-1]
        if self.identity:
            return np.einsum("ikm,jkm->ijm", Ft, Ft, out=ws(self.name + "FMF", (3, 3, m)))
        if self.M_t is None:
            FM = np.einsum("ikm,kj->ijm", Ft, self.matrix, out=ws("FM", (3, 3, m)))
        else:
            FM = np.einsum("ikm,kjm->ijm", Ft, self.M_t, out=ws("FM", (3, 3, m)))
        return np.einsum("ikm,jkm->ijm", FM, Ft, out=ws(self.name + "FMF", (3, 3, m)))


def tangent_slots(
    groups: Sequence[TermGroup], Dt: np.ndarray
) -> Dict[Tuple[str, Hashable], TangentSlot]:
    """One slot per distinct (kind, matrix) of the groups' tangent pairs, by slot_key.

    Raises:
        ValueError: a per-cell matrix (e.g. a Costa frame) held for another number of cells.
    """
    m = Dt.shape[-1]
    slots: Dict[Tuple[str, Hashable], TangentSlot] = {}
    for group in groups:
        for term in group.terms:
            for pair in term.g.tangent:
                if pair.kind != "spectral" and pair.matrix.ndim == 3 and len(pair.matrix) != m:
                    raise ValueError(
                        "the material holds per-cell data (e.g. a Costa frame) for "
                        f"{len(pair.matrix)} cells, but the mesh has {m} cells"
                    )
                key = slot_key(pair)
                if key not in slots:
                    slots[key] = TangentSlot(pair.kind, pair.matrix, Dt, len(slots))
    return slots


@dataclass(frozen=True)
class MeshConstants:
    """What the edge blocks need of the mesh, precomputed once, component-major.

    Dt: (3, 4, m) rest shape vectors D_a. DxD: (3, 6, m) D_a x D_b per edge. volumes: (m,)
    rest volumes. slots: the material's tangent slots (see :func:`tangent_slots`). DtV:
    (3, 4, m) V0 D_a, so the gradient V0 P D_a costs no extra product.
    """

    Dt: np.ndarray
    DxD: np.ndarray
    volumes: np.ndarray
    slots: Mapping[Tuple[str, Hashable], TangentSlot]
    DtV: np.ndarray


def edge_blocks(
    mesh: MeshConstants,
    state: CellState,
    agg: Aggregates,
    *,
    regularize: bool,
    ws: Workspace,
    out: Optional[np.ndarray] = None,
) -> np.ndarray:
    """The (3, 3, 6, m) edge blocks of every cell, multiplied by the rest volumes.

    Args:
        mesh: the per-mesh constants. state: the cells at x. agg: the folded aggregates.
        regularize: the compressed-element regularisation of the paper's section 2.3.
        ws: work arrays. out: optional (3, 3, 6, m) array the blocks are written to.
    """
    Dt = mesh.Dt
    m = Dt.shape[-1]
    Ft, kin = state.Ft, state.kin
    S, S_hat, h, g2 = agg.S, agg.S_hat, agg.h, agg.g2
    tmp4 = ws("tmp4", (4, m))
    outers: List[Tuple[np.ndarray, str, np.ndarray, str]] = []
    scaled: List[Tuple[np.ndarray, np.ndarray]] = []  # s (6, m), M (3, 3, m)
    diag = ws("diag", (6, m))  # coefficient of Id
    diag.fill(0.0)
    edge_tmp = ws("edge_tmp", (6, m))

    # geometric: (D_a . S D_b) Id
    if S is not None:
        S_t = np.broadcast_to(S[:, :, None], (3, 3, m)) if np.ndim(S) == 2 else S
        diag += edge_dot(Dt, apply_matrix(S_t, Dt, out=ws("SD", (3, 4, m)), tmp=tmp4), out=edge_tmp)

    # material: the declared tangent pairs
    G_of: Dict[int, np.ndarray] = {}
    for key, slot in mesh.slots.items():
        w = agg.weights.get(key)
        if w is None or is_zero(w):
            continue
        if slot.kind == "spectral":
            for wn, yn in _spectral_outers(np.broadcast_to(w, (m, 3, 3)), kin, Dt, ws):
                outers.append((wn, "cell", yn, "edge"))
            continue
        G = G_of.get(id(slot.MD))  # slots of both kinds with the same M share F M D_a
        if G is None:
            G = G_of[id(slot.MD)] = apply_matrix(
                Ft, slot.MD, out=ws(slot.name + "G", (3, 4, m)), tmp=tmp4
            )
        Gw = ws(slot.name + "Gw", (3, 4, m))
        if slot.kind == "first":
            np.multiply(G, 2.0 * w, out=Gw)
            outers.append((Gw, "a", G, "b"))
        else:
            np.multiply(G, w, out=Gw)
            outers.append((Gw, "b", G, "a"))
            scaled.append(
                (np.multiply(slot.DMD, w, out=ws(slot.name + "s", (6, m))), slot.FMFt(Ft, ws))
            )

    # regularisation (section 2.3): c v_a (x) v_b -> c [(1 - b) v_a (x) v_b + b (v_a . v_b) Id]
    b = np.clip(1.0 - kin.J, 0.0, 1.0) if regularize else None
    keep = None if b is None else 1.0 - b

    # g2 d_a (x) d_b, folded into the volumetric coupling d_a (x) F S-hat D_b when present
    dJ = state.dJ() if (g2 is not None or S_hat is not None) else None
    g2_vec = None
    if g2 is not None:
        g2_vec = np.multiply(dJ, g2 if keep is None else g2 * keep, out=ws("g2_vec", (3, 4, m)))
        if b is not None:
            edge_tmp = edge_dot(dJ, dJ, out=edge_tmp)
            edge_tmp *= g2 * b
            diag += edge_tmp
    if S_hat is not None:
        FSD = stress_node_vectors(state, S_hat, None, ws("FSD", (3, 4, m)))
        v = FSD if g2_vec is None else np.add(FSD, g2_vec, out=ws("FSD_g2", (3, 4, m)))
        outers.append((dJ, "a", v, "b"))
        outers.append((FSD, "a", dJ, "b"))
    elif g2_vec is not None:
        outers.append((dJ, "a", g2_vec, "b"))

    # exponential groups: c e^u du (x) du, regularised like g2
    for k, (c, du) in enumerate(agg.rank_one):
        outers.append(
            (
                np.multiply(du, c if keep is None else c * keep, out=ws(f"du_s{k}", (3, 4, m))),
                "a",
                du,
                "b",
            )
        )
        if b is not None:
            edge_tmp = edge_dot(du, du, out=edge_tmp)
            edge_tmp *= c * b
            diag += edge_tmp

    # h d2J/dx_a dx_b = h eps_rcq (F (D_a x D_b))_q, a skew matrix
    skew = None
    if h is not None:
        skew = apply_matrix(Ft, mesh.DxD, out=ws("skew", (3, 6, m)), tmp=ws("tmp6", (6, m)))
        skew *= h

    return _sum_components(outers, scaled, diag, skew, mesh.volumes, out, ws("tmp_3m", (3, m)))


# Skew part: component (r, c) gets sign * v[q].
_SKEW = {
    (0, 1): (2, 1.0),
    (1, 0): (2, -1.0),
    (0, 2): (1, -1.0),
    (2, 0): (1, 1.0),
    (1, 2): (0, 1.0),
    (2, 1): (0, -1.0),
}


# The edges grouped by their first node a: edges e0..e1 are (a, a+1), ..., (a, 3).
_SEGMENTS = ((0, 0, 3), (1, 3, 5), (2, 5, 6))


def _part(x: np.ndarray, where: str, k: int, a: int, e0: int, e1: int) -> np.ndarray:
    """Component k of a vector field on the edges e0..e1 that start at node a, (n, m) or
    broadcastable to it: per node at the edge's first ("a") or second ("b") node, per edge,
    or per cell.
    """
    if where == "a":
        return x[k, a][None]
    if where == "b":
        return x[k, a + 1 :]
    if where == "edge":
        return x[k, e0:e1]
    return x[k][None]


def _sum_components(outers, scaled, diag, skew, V0, out, tmp) -> np.ndarray:
    """K[r, c, e] = sum u[r] v[c] + sum s M[r, c] + [r == c] diag + skew, times V0, (3, 3, 6, m).

    Block component (r, c) is built for the edges sharing their first node at once (3, 2
    and 1 edges), reading node vectors in place (no per-edge copies), so the running sum
    and its scratch stay in cache.
    """
    m = len(V0)
    K = np.empty((3, 3, 6, m)) if out is None else out
    for r in range(3):
        for c in range(3):
            for a, e0, e1 in _SEGMENTS:
                row = K[r, c, e0:e1]
                t = tmp[: e1 - e0]
                started = False
                for u, uw, v, vw in outers:
                    np.multiply(
                        _part(u, uw, r, a, e0, e1),
                        _part(v, vw, c, a, e0, e1),
                        out=t if started else row,
                    )
                    if started:
                        row += t
                    started = True
                for s_, M in scaled:
                    np.multiply(s_[e0:e1], M[r, c], out=t if started else row)
                    if started:
                        row += t
                    started = True
                if not started:
                    row.fill(0.0)
                if r == c:
                    row += diag[e0:e1]
                if skew is not None and (r, c) in _SKEW:
                    q, sign = _SKEW[(r, c)]
                    if sign > 0:
                        row += skew[q, e0:e1]
                    else:
                        row -= skew[q, e0:e1]
                row *= V0
    return K


def _spectral_outers(
    theta: np.ndarray, kin, Dt: np.ndarray, ws: Workspace
) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Edge blocks of sum_{n,l} theta_nl P_n H P_l, P_n = v_n v_n^T (eigenprojectors of C),
    as three outer products w_n (x) y_n.

    With w_n = F v_n and c_na = v_n . D_a, block (a, b) is
    sum_{n,l} theta_nl [c_nb c_la w_n (x) w_l + c_lb c_la w_n (x) w_n]
    = sum_n w_n (x) y_n,  y_n = c_nb sum_l theta_nl c_la w_l + (sum_l theta_nl c_lb c_la) w_n.

    theta: (m, 3, 3). Returns [(w_n (3, m), y_n (3, 6, m))] for n = 0, 1, 2.
    """
    m = Dt.shape[-1]
    V_t = to_component_major(kin.eig[1], out=ws("V_t", (3, 3, m)))  # [j, n] = (v_n)_j
    # w[n, i] = (F v_n)_i and c[n, a] = v_n . D_a
    w = np.einsum("ikm,knm->nim", kin.Ft, V_t, out=ws("spec_w", (3, 3, m)))
    c = np.einsum("jnm,jam->nam", V_t, Dt, out=ws("spec_c", (3, 4, m)))
    ca, cb = np.take(c, _EA, axis=1), np.take(c, _EB, axis=1)  # (3, 6, m)
    T = to_component_major(theta, out=ws("spec_T", (3, 3, m)))
    tc = ws("spec_tc", (6, m))
    tmp = ws("spec_tmp", (6, m))
    r = ws("spec_r", (6, m))
    result = []
    for n in range(3):
        y = ws(f"spec_y{n}", (3, 6, m))
        y.fill(0.0)
        r.fill(0.0)
        for l in range(3):
            np.multiply(T[n, l], ca[l], out=tc)
            for i in range(3):
                np.multiply(tc, w[l, i], out=tmp)
                y[i] += tmp
            np.multiply(tc, cb[l], out=tmp)
            r += tmp
        y *= cb[n]
        for i in range(3):
            np.multiply(r, w[n, i], out=tmp)
            y[i] += tmp
        result.append((w[n], y))
    return result


def edge_blocks_to_element_matrices(blocks: np.ndarray) -> np.ndarray:
    """Full element matrices from the six edge blocks.

    Args:
        blocks: (m, 6, 3, 3) d2W/dx_a dx_b for the edges of EDGES (any memory layout).

    Returns:
        (m, 12, 12), dof order (node 0: x, y, z, node 1: ...).
    """
    m = len(blocks)
    K = np.zeros((m, 4, 3, 4, 3))
    for e, (a, b) in enumerate(EDGES):
        Kab = blocks[:, e]
        K[:, a, :, b, :] = Kab
        K[:, b, :, a, :] = np.swapaxes(Kab, 1, 2)
        K[:, a, :, a, :] -= Kab
        K[:, b, :, b, :] -= np.swapaxes(Kab, 1, 2)
    return K.reshape(m, 12, 12)
