"""The generic MJED engine: term groups in, element forces and edge stiffness blocks out.

For one group with u = sum_k f_k g_k, S-bar = sum_k f_k S_k, S-hat = sum_k f'_k S_k,
h = sum_k f'_k g_k and g2 = sum_k f''_k g_k (paper, eqs. 3-4; d_a = dJ/dx_a = cof(F) D_a):

    du/dx_a      = F S-bar D_a + h d_a
    d2u/dx_a dx_b = (D_a . S-bar D_b) Id                        geometric
                 + sum_k f_k [first: 2 beta (F A D_a)(x)(F A D_b)
                              second: gamma ((F B D_b)(x)(F B D_a) + (D_a . B D_b) F B F^T)]
                 + d_a (x) F S-hat D_b + F S-hat D_a (x) d_b
                 + g2 d_a (x) d_b                               (regularised, section 2.3)
                 + h d2J/dx_a dx_b,   [d2J/dx_a dx_b]_ij = eps_ijq (F (D_a x D_b))_q

A plain group contributes c u, an exponential group c e^u, whose Hessian adds
c e^u du (x) du. Everything but that rank-one term is linear in the group's aggregates, so
all groups are folded into one set of aggregates (weighted by c or c e^u) before the 3x3
algebra. Only the six edge blocks (a < b) are formed: K_ba = K_ab^T and, because the energy
is invariant under translation, K_aa = -sum_{b != a} K_ab.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Tuple

import numpy as np

from mjed.kinematics import Kinematics, deformation_gradient
from mjed.terms import IDENTITY, TangentPair, TermGroup

__all__ = ["EDGES", "MJEDEngine", "Evaluation", "edge_blocks_to_element_matrices"]

#: The six edges (a, b), a < b, of a tetrahedron, in the order of the edge axis.
EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
_EA, _EB = EDGES[:, 0], EDGES[:, 1]
_DIAG = (np.arange(3), np.arange(3))


@dataclass
class Evaluation:
    """Per-cell results at one state, all per cell (multiplied by the rest volume).

    energy: (m,); gradient: (m, 4, 3) dW/dx_a; edge_blocks: (m, 6, 3, 3) d2W/dx_a dx_b for
    the edges of EDGES (None if not requested); J: (m,); F: (m, 3, 3); pk2: (m, 3, 3) second
    Piola-Kirchhoff stress 2 dW/dC per unit rest volume (None if not requested).
    """

    energy: np.ndarray
    gradient: np.ndarray
    edge_blocks: "np.ndarray | None"
    J: np.ndarray
    F: "np.ndarray | None" = None
    pk2: "np.ndarray | None" = None


class _Slot:
    """A (kind, matrix) tangent slot shared by all pairs with the same constant matrix.

    Precomputed once per mesh: M D_a (m, 4, 3) and, for the second kind, D_a . M D_b (m, 6).
    """

    def __init__(self, kind: str, matrix: np.ndarray, D: np.ndarray):
        self.kind = kind
        self.matrix = matrix
        if kind == "spectral":  # eigenprojectors of C: nothing to precompute
            self.identity = False
            return
        self.identity = matrix is IDENTITY or (matrix.shape == (3, 3) and np.array_equal(matrix, IDENTITY))
        if self.identity:
            self.MD = D
        elif matrix.ndim == 2:
            self.MD = np.einsum("ij,maj->mai", matrix, D)
        else:
            self.MD = np.einsum("mij,maj->mai", matrix, D)
        if kind == "second":
            self.DMD = np.einsum("mei,mei->me", D[:, _EA], self.MD[:, _EB])


def _slot_key(pair: TangentPair) -> Tuple[str, object]:
    if pair.kind == "spectral":
        return pair.kind, None
    m = pair.matrix
    if m.ndim == 2:
        return pair.kind, m.tobytes()
    return pair.kind, id(m)


class MJEDEngine:
    """Evaluates a material's term groups on every cell of a mesh at once.

    Args:
        D: (m, 4, 3) rest shape vectors.
        volumes: (m,) rest volumes.
        groups: the material's term groups.
        regularize: apply the compressed-element regularisation of the paper's section 2.3.
    """

    def __init__(self, D: np.ndarray, volumes: np.ndarray, groups: Tuple[TermGroup, ...], *, regularize: bool = False):
        self.D = D
        self.volumes = volumes
        self.groups = groups
        self.regularize = regularize
        self._slots: Dict[Tuple[str, object], _Slot] = {}
        for group in groups:
            for term in group.terms:
                for pair in term.g.tangent:
                    if pair.kind != "spectral" and pair.matrix.ndim == 3 and len(pair.matrix) != len(D):
                        raise ValueError(
                            f"the material holds per-cell data (e.g. a Costa frame) for {len(pair.matrix)} cells, "
                            f"but the mesh has {len(D)} cells"
                        )
                    key = _slot_key(pair)
                    if key not in self._slots:
                        self._slots[key] = _Slot(pair.kind, pair.matrix, D)
        # D_a x D_b per edge, for the second derivative of J.
        self._DxD = np.cross(D[:, _EA], D[:, _EB])

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, x_cells: np.ndarray, *, stiffness: bool = True, check_J=None, pk2: bool = False) -> Evaluation:
        """Energy, gradient and (optionally) edge stiffness blocks of every cell.

        Args:
            x_cells: (m, 4, 3) current positions of each cell's nodes.
            stiffness: also compute the edge blocks.
            check_J: called with J (m,) before any material function is evaluated, so a
                caller can refuse inverted cells before ln J or J^p produce NaN.
            pk2: also return S = 2 dW/dC = sum c f_k S_k + h J C^-1 (for viscous models).
        """
        D = self.D
        m = len(D)
        kin = Kinematics(deformation_gradient(x_cells, D))
        F, J = kin.F, kin.J
        if check_J is not None:
            check_J(J)
        dJ = D @ np.swapaxes(kin.cof, 1, 2)  # (m, 4, 3): d_a = cof D_a

        energy = np.zeros(m)
        S = np.zeros((m, 3, 3))  # sum over groups of c * S-bar
        S_hat = np.zeros((m, 3, 3))
        h = np.zeros(m)
        g2 = np.zeros(m)
        weights = {key: 0.0 for key in self._slots}  # (m,) arrays, (m, 3, 3) for "spectral"
        rank_one: List[Tuple[np.ndarray, np.ndarray]] = []

        for group in self.groups:
            agg = _GroupAggregates(m)
            for term in group.terms:
                agg.add(term, kin, J)
            if group.exponential:
                scale = group.coefficient * np.exp(agg.u)
                energy += scale
                du = D @ np.swapaxes(F @ agg.S, 1, 2) + agg.h[:, None, None] * dJ
                rank_one.append((scale, du))
            else:
                scale = group.coefficient
                energy += scale * agg.u
            S += _scale(scale, agg.S)
            S_hat += _scale(scale, agg.S_hat)
            h += scale * agg.h
            g2 += scale * agg.g2
            for key, w in agg.pair_weights.items():
                weights[key] = weights[key] + _scale(scale, w)

        V0 = self.volumes
        FSD = D @ np.swapaxes(F @ S, 1, 2)  # (m, 4, 3): F S D_a
        gradient = (FSD + h[:, None, None] * dJ) * V0[:, None, None]
        blocks = None
        if stiffness:
            blocks = self._edge_blocks(kin, dJ, S, S_hat, h, g2, weights, rank_one)
            blocks *= V0[:, None, None, None]
        S_total = None
        if pk2:
            # dJ/dC = J C^-1 / 2 and J C^-1 = cof^T cof / J.
            S_total = S + (h / J)[:, None, None] * np.einsum("mki,mkj->mij", kin.cof, kin.cof)
        return Evaluation(energy * V0, gradient, blocks, J, F, S_total)

    def _edge_blocks(self, kin, dJ, S, S_hat, h, g2, weights, rank_one) -> np.ndarray:
        F, J, D = kin.F, kin.J, self.D
        m = len(D)
        K = np.zeros((m, 6, 3, 3))
        Da, Db = D[:, _EA], D[:, _EB]
        da, db = dJ[:, _EA], dJ[:, _EB]

        # geometric: (D_a . S D_b) Id
        SD = D @ S  # S symmetric: rows are (S D_a)^T
        geo = np.einsum("mei,mei->me", Da, SD[:, _EB])
        K[:, :, _DIAG[0], _DIAG[1]] += geo[:, :, None]

        # material: the declared tangent pairs
        for key, slot in self._slots.items():
            w = np.broadcast_to(weights[key], (m,) if slot.kind != "spectral" else (m, 3, 3))
            if slot.kind == "spectral":
                K += _spectral_blocks(w, kin, D)
                continue
            FMD = slot.MD @ np.swapaxes(F, 1, 2)  # (m, 4, 3): F M D_a
            Ga, Gb = FMD[:, _EA], FMD[:, _EB]
            if slot.kind == "first":
                K += (2.0 * w)[:, None, None, None] * Ga[:, :, :, None] * Gb[:, :, None, :]
            else:
                FMF = F @ np.swapaxes(F, 1, 2) if slot.identity else F @ _cellwise(slot.matrix, m) @ np.swapaxes(F, 1, 2)
                K += w[:, None, None, None] * (
                    Gb[:, :, :, None] * Ga[:, :, None, :] + slot.DMD[:, :, None, None] * FMF[:, None, :, :]
                )

        # volumetric coupling: d_a (x) F S-hat D_b + F S-hat D_a (x) d_b
        FSD = D @ np.swapaxes(F @ S_hat, 1, 2)
        K += da[:, :, :, None] * FSD[:, _EB][:, :, None, :] + FSD[:, _EA][:, :, :, None] * db[:, :, None, :]

        # outer products of J gradients (and of exponential-group gradients), regularised
        b = np.clip(1.0 - J, 0.0, 1.0) if self.regularize else None
        K += _regularised_outer(g2, da, db, b)
        for scale, du in rank_one:
            K += _regularised_outer(scale, du[:, _EA], du[:, _EB], b)

        # h d2J/dx_a dx_b, a skew matrix
        v = (self._DxD @ np.swapaxes(F, 1, 2)) * h[:, None, None]
        K[:, :, 0, 1] += v[:, :, 2]
        K[:, :, 1, 0] -= v[:, :, 2]
        K[:, :, 0, 2] -= v[:, :, 1]
        K[:, :, 2, 0] += v[:, :, 1]
        K[:, :, 1, 2] += v[:, :, 0]
        K[:, :, 2, 1] -= v[:, :, 0]
        return K


class _GroupAggregates:
    """Running sums of one group's terms: u, S-bar, S-hat, h, g2 and the tangent weights."""

    def __init__(self, m: int):
        self.m = m
        self.u = np.zeros(m)
        self.S = np.zeros((m, 3, 3))
        self.S_hat = np.zeros((m, 3, 3))
        self.h = np.zeros(m)
        self.g2 = np.zeros(m)
        self.pair_weights: Dict[Tuple[str, object], np.ndarray] = {}

    def add(self, term, kin, J) -> None:
        f, df, d2f = term.f(J)
        g = term.g.value(kin)
        self.u += f * g
        self.h += df * g
        self.g2 += d2f * g
        Sk = term.g.stress(kin)
        if Sk is not None:
            self.S += _scale(f, Sk)
            self.S_hat += _scale(df, Sk)
        for pair, coef in zip(term.g.tangent, term.g.tangent_coefficients(kin)):
            key = _slot_key(pair)
            self.pair_weights[key] = self.pair_weights.get(key, 0.0) + _scale(f, coef)


def _spectral_blocks(theta: np.ndarray, kin: Kinematics, D: np.ndarray) -> np.ndarray:
    """Edge blocks of sum_{n,l} theta_nl P_n H P_l, P_n = v_n v_n^T (eigenprojectors of C).

    With w_n = F v_n and c_na = v_n . D_a, block (a, b) is
    sum_{n,l} theta_nl [c_nb c_la w_n (x) w_l + c_lb c_la w_n (x) w_n].

    theta: (m, 3, 3). Returns (m, 6, 3, 3).
    """
    V = kin.eig[1]  # (m, 3, 3), columns v_n
    w = np.einsum("mij,mjn->mni", kin.F, V)  # (m, 3, 3): w[:, n] = F v_n
    c = np.einsum("mjn,maj->mna", V, D)  # (m, 3, 4)
    ca, cb = c[:, :, _EA], c[:, :, _EB]  # (m, 3, 6)
    cross = np.einsum("mnl,mne,mle->menl", theta, cb, ca)
    K = np.einsum("menl,mni,mlj->meij", cross, w, w)
    diag = np.einsum("mnl,mle,mle->men", theta, cb, ca)
    K += np.einsum("men,mni,mnj->meij", diag, w, w)
    return K


def _scale(s, A):
    """s * A with s per cell, (m,) or scalar, and A (m, ...) or scalar."""
    if np.ndim(s) == 0 or np.ndim(A) <= 1:
        return s * A
    return np.reshape(s, np.shape(s) + (1,) * (np.ndim(A) - 1)) * A


def _cellwise(matrix: np.ndarray, m: int) -> np.ndarray:
    return np.broadcast_to(matrix, (m, 3, 3)) if matrix.ndim == 2 else matrix


def _regularised_outer(scale, va: np.ndarray, vb: np.ndarray, b) -> np.ndarray:
    """scale [(1 - b) va (x) vb + b (va . vb) Id] per edge; b None means b = 0.

    va, vb: (m, 6, 3); scale, b: (m,) or scalars. Returns (m, 6, 3, 3).
    """
    s = np.broadcast_to(np.asarray(scale, dtype=float), (va.shape[0],))
    outer = va[:, :, :, None] * vb[:, :, None, :]
    if b is None:
        return s[:, None, None, None] * outer
    out = (s * (1.0 - b))[:, None, None, None] * outer
    dot = np.einsum("mei,mei->me", va, vb) * (s * b)[:, None]
    out[:, :, _DIAG[0], _DIAG[1]] += dot[:, :, None]
    return out


def edge_blocks_to_element_matrices(blocks: np.ndarray) -> np.ndarray:
    """Full element matrices from the six edge blocks.

    Args:
        blocks: (m, 6, 3, 3) d2W/dx_a dx_b for the edges of EDGES.

    Returns:
        (m, 12, 12), dof order (node 0: x, y, z, node 1: ...).
    """
    m = len(blocks)
    K = np.zeros((m, 4, 4, 3, 3))
    K[:, _EA, _EB] = blocks
    K[:, _EB, _EA] = np.swapaxes(blocks, 2, 3)
    for a in range(4):
        K[:, a, a] = -K[:, a].sum(axis=1)
    return K.transpose(0, 1, 3, 2, 4).reshape(m, 12, 12)
