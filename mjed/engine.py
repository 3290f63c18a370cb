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

Layout (why it is fast): the 3x3 algebra runs on "component-major" arrays whose cell axis is
last and contiguous, vectors per node (3, 4, m), per edge (3, 6, m), matrices (3, 3, m) and
edge blocks (3, 3, 6, m). Every NumPy operation then streams long contiguous rows instead of
broadcasting over tiny 3x3 trailing axes (about 15x faster for the outer products), and each
of the nine block components is summed in a cache-sized (6, m) slab. The public Evaluation
exposes the same arrays as (m, 4, 3) and (m, 6, 3, 3) views.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Tuple

import numpy as np

from mjed.kinematics import Kinematics
from mjed.sparse import EDGES
from mjed.terms import IDENTITY, TangentPair, TermGroup

__all__ = ["EDGES", "MJEDEngine", "Evaluation", "edge_blocks_to_element_matrices"]

_EA, _EB = EDGES[:, 0], EDGES[:, 1]


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


@dataclass
class SoAEvaluation:
    """The engine's native result: the same quantities in component-major layout.

    energy: (m,); gradient: (3, 4, m) with [k, a] = dW/dx_a,k; blocks: (3, 3, 6, m) with
    [r, c, e] = (d2W/dx_a dx_b)_rc for edge e = (a, b), or None; J: (m,); F: (m, 3, 3);
    pk2: (m, 3, 3) or None. All per cell, multiplied by the rest volume where it applies.
    """

    energy: np.ndarray
    gradient: np.ndarray
    blocks: "np.ndarray | None"
    J: np.ndarray
    F: np.ndarray
    pk2: "np.ndarray | None" = None

    def public(self) -> Evaluation:
        """The (m, ...) views of the public Evaluation (no copy)."""
        blocks = None if self.blocks is None else self.blocks.transpose(3, 2, 0, 1)
        return Evaluation(self.energy, self.gradient.transpose(2, 1, 0), blocks, self.J, self.F, self.pk2)


class _Scratch:
    """Named work arrays kept from one evaluation to the next.

    Fresh NumPy temporaries of a few MB cost page faults on every call (the allocator hands
    large blocks back to the OS when they are freed), which on a 20k-cell mesh was about as
    expensive as the arithmetic. Intermediates are therefore written into these buffers,
    allocated on the first call and reused; what an evaluation returns is never one of them.
    One arena per engine: an engine must not evaluate from two threads at once.
    """

    def __init__(self):
        self._arrays: Dict[str, np.ndarray] = {}

    def __call__(self, name: str, shape: Tuple[int, ...]) -> np.ndarray:
        a = self._arrays.get(name)
        if a is None or a.shape != shape:
            a = self._arrays[name] = np.empty(shape)
        return a


def _soa(A: np.ndarray, out: "np.ndarray | None" = None) -> np.ndarray:
    """(m, ...) -> (..., m), contiguous (into ``out`` if given)."""
    if out is None:
        return np.ascontiguousarray(np.moveaxis(A, 0, -1))
    np.copyto(out, np.moveaxis(A, 0, -1))
    return out


def _apply(A: np.ndarray, V: np.ndarray, out: "np.ndarray | None" = None, tmp: "np.ndarray | None" = None) -> np.ndarray:
    """A V per cell: A (3, 3, m), V (3, k, m) -> (3, k, m), out[i] = sum_j A[i, j] V[j]."""
    if out is None:
        out = np.empty((3,) + V.shape[1:])
    if tmp is None:
        tmp = np.empty(V.shape[1:])
    for i in range(3):
        np.multiply(A[i, 0], V[0], out=out[i])
        for j in (1, 2):
            np.multiply(A[i, j], V[j], out=tmp)
            out[i] += tmp
    return out


def _is_zero(x) -> bool:
    return np.ndim(x) == 0 and x == 0


def _add(acc, value):
    """acc + value where None stands for zero (so absent terms cost nothing)."""
    if value is None:
        return acc
    return value if acc is None else acc + value


class _Slot:
    """A (kind, matrix) tangent slot shared by all pairs with the same constant matrix.

    Precomputed once per mesh, component-major: M D_a (3, 4, m), the matrix itself per cell
    (3, 3, m) when it varies, and, for the second kind, D_a . M D_b (6, m).
    """

    def __init__(self, kind: str, matrix: np.ndarray, D: np.ndarray, Dt: np.ndarray, index: int):
        self.kind = kind
        self.matrix = matrix
        self.name = f"slot{index}"
        if kind == "spectral":  # eigenprojectors of C: nothing to precompute
            self.identity = False
            return
        self.identity = matrix is IDENTITY or (matrix.shape == (3, 3) and np.array_equal(matrix, IDENTITY))
        self.M_t = None if matrix.ndim == 2 else _soa(matrix)
        if self.identity:
            self.MD = Dt
        elif matrix.ndim == 2:
            self.MD = np.einsum("ij,jam->iam", matrix, Dt)
        else:
            self.MD = _apply(self.M_t, Dt)
        if kind == "second":
            self.DMD = _edge_dot(Dt, self.MD)

    def FMFt(self, Ft: np.ndarray, ws: _Scratch) -> np.ndarray:
        """F M F^T, (3, 3, m)."""
        m = Ft.shape[-1]
        if self.identity:
            return np.einsum("ikm,jkm->ijm", Ft, Ft, out=ws(self.name + "FMF", (3, 3, m)))
        if self.M_t is None:
            FM = np.einsum("ikm,kj->ijm", Ft, self.matrix, out=ws("FM", (3, 3, m)))
        else:
            FM = np.einsum("ikm,kjm->ijm", Ft, self.M_t, out=ws("FM", (3, 3, m)))
        return np.einsum("ikm,jkm->ijm", FM, Ft, out=ws(self.name + "FMF", (3, 3, m)))


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

    Work arrays are kept between calls (see _Scratch): do not evaluate one engine from two
    threads at once.
    """

    def __init__(self, D: np.ndarray, volumes: np.ndarray, groups: Tuple[TermGroup, ...], *, regularize: bool = False):
        self.D = D
        self.volumes = volumes
        self.groups = groups
        self.regularize = regularize
        # Per-mesh constants, component-major: D (3, 4, m) and D_a x D_b (3, 6, m).
        self._Dt = np.ascontiguousarray(D.transpose(2, 1, 0))
        self._DxD = _soa(np.cross(D[:, _EA], D[:, _EB]).transpose(0, 2, 1))
        self._ws = _Scratch()
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
                        self._slots[key] = _Slot(pair.kind, pair.matrix, D, self._Dt, len(self._slots))

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, x_cells: np.ndarray, *, stiffness: bool = True, check_J=None, pk2: bool = False) -> Evaluation:
        """Energy, gradient and (optionally) edge stiffness blocks of every cell.

        Args:
            x_cells: (m, 4, 3) current positions of each cell's nodes.
            stiffness: also compute the edge blocks.
            check_J: called with J (m,) before any material function is evaluated, so a
                caller can refuse inverted cells before ln J or J^p produce NaN.
            pk2: also return S = 2 dW/dC = sum c f_k S_k + h J C^-1 (for viscous models).

        The gradient and edge blocks are views of component-major arrays (see the module
        docstring); use :meth:`evaluate_soa` for those arrays themselves.
        """
        x_t = np.ascontiguousarray(np.asarray(x_cells, dtype=np.float64).transpose(2, 1, 0))
        return self.evaluate_soa(x_t, stiffness=stiffness, check_J=check_J, pk2=pk2).public()

    def evaluate_soa(self, x_t: np.ndarray, *, stiffness: bool = True, check_J=None, pk2: bool = False,
                     out: "np.ndarray | None" = None) -> SoAEvaluation:
        """As :meth:`evaluate`, in component-major layout.

        x_t: (3, 4, m) current positions, [k, a] = x_a,k of each cell (contiguous).
        out: optional (3, 3, 6, m) float64 array the edge blocks are written to (a caller
            that consumes the blocks at once can reuse one buffer between calls).
        """
        D, Dt, ws = self.D, self._Dt, self._ws
        m = len(D)
        # F_ij = sum_a x_a,i D_a,j, formed component-major and copied once to (m, 3, 3).
        Ft = np.einsum("iam,jam->ijm", x_t, Dt, out=ws("Ft", (3, 3, m)))
        kin = Kinematics(np.ascontiguousarray(np.moveaxis(Ft, -1, 0)), Ft=Ft,
                         cof_out=ws("cof_t", (3, 3, m)), C_out=ws("C_t", (3, 3, m)))
        F, J = kin.F, kin.J
        if check_J is not None:
            check_J(J)
        tmp4 = ws("tmp4", (4, m))
        cache: Dict[str, np.ndarray] = {}

        def dJ_of() -> np.ndarray:
            """d_a = cof D_a, (3, 4, m), formed on first use (St Venant-Kirchhoff never needs it)."""
            if "dJ" not in cache:
                cache["dJ"] = _apply(kin.cof_t, Dt, out=ws("dJ", (3, 4, m)), tmp=tmp4)
            return cache["dJ"]

        energy = np.zeros(m)
        S = S_hat = h = g2 = None  # sums over groups (weighted by c or c e^u); None is zero
        weights: Dict[Tuple[str, object], object] = {}
        rank_one: List[Tuple[np.ndarray, np.ndarray]] = []  # (c e^u (m,), du (3, 4, m))
        for group in self.groups:
            agg = _GroupAggregates(m)
            for term in group.terms:
                agg.add(term, kin, J)
            if group.exponential:
                scale = group.coefficient * np.exp(agg.u)
                energy += scale
                if stiffness:
                    du = self._vector_field(Ft, agg.S, agg.h, dJ_of, ws(f"du{len(rank_one)}", (3, 4, m)))
                    rank_one.append((scale, du))
            else:
                scale = group.coefficient
                energy += scale * agg.u
            S = _add(S, _scale_opt(scale, agg.S))
            S_hat = _add(S_hat, _scale_opt(scale, agg.S_hat))
            h = _add(h, None if agg.h is None else scale * agg.h)
            g2 = _add(g2, None if agg.g2 is None else scale * agg.g2)
            for key, w in agg.pair_weights.items():
                weights[key] = _add(weights.get(key), _scale(scale, w))

        V0 = self.volumes
        gradient = self._vector_field(Ft, S, h, dJ_of, np.empty((3, 4, m)))
        gradient *= V0
        blocks = None
        if stiffness:
            blocks = self._edge_blocks(Ft, kin, dJ_of, S, S_hat, h, g2, weights, rank_one, out)
        S_total = None
        if pk2:
            # dJ/dC = J C^-1 / 2 and J C^-1 = cof^T cof / J.
            S_total = np.zeros((m, 3, 3)) if S is None else np.array(np.broadcast_to(S, (m, 3, 3)))
            if h is not None:
                S_total += (h / J)[:, None, None] * np.moveaxis(np.einsum("kim,kjm->ijm", kin.cof_t, kin.cof_t), -1, 0)
        return SoAEvaluation(energy * V0, gradient, blocks, J, F, S_total)

    def _vector_field(self, Ft, S, h, dJ_of, out) -> np.ndarray:
        """F S D_a + h d_a into ``out`` (3, 4, m); S (m, 3, 3) or None, h (m,) or None,
        dJ_of a callable giving d_a (3, 4, m)."""
        ws, Dt = self._ws, self._Dt
        m = Dt.shape[-1]
        if S is None:
            out.fill(0.0)
        else:
            S_t = _soa(np.broadcast_to(S, (m, 3, 3)), out=ws("S_t", (3, 3, m)))
            FS = np.einsum("ikm,kjm->ijm", Ft, S_t, out=ws("FS", (3, 3, m)))
            _apply(FS, Dt, out=out, tmp=ws("tmp4", (4, m)))
        if h is not None:
            tmp = ws("tmp34", (3, 4, m))
            np.multiply(dJ_of(), h, out=tmp)
            out += tmp
        return out

    def _edge_blocks(self, Ft, kin, dJ_of, S, S_hat, h, g2, weights, rank_one, out) -> np.ndarray:
        """The (3, 3, 6, m) edge blocks, multiplied by the rest volumes (dJ_of: a callable
        giving d_a, see evaluate_soa).

        Every contribution is gathered as one of: an outer product u_a (x) v_b (u, v given
        per node (3, 4, m), per edge (3, 6, m) or per cell (3, m)), a per-edge scalar times a
        per-cell matrix, a per-edge scalar times Id, or the skew term of d2J; the 54 rows
        (r, c, edge) of the result are then summed one at a time, reading node vectors in
        place (no per-edge copies).
        """
        Dt, ws = self._Dt, self._ws
        m = Dt.shape[-1]
        tmp4 = ws("tmp4", (4, m))
        outers: List[Tuple[np.ndarray, str, np.ndarray, str]] = []
        scaled: List[Tuple[np.ndarray, np.ndarray]] = []  # s (6, m), M (3, 3, m)
        diag = ws("diag", (6, m))  # coefficient of Id
        diag.fill(0.0)
        edge_tmp = ws("edge_tmp", (6, m))

        # geometric: (D_a . S D_b) Id
        if S is not None:
            S_t = _soa(np.broadcast_to(S, (m, 3, 3)), out=ws("S_t", (3, 3, m)))
            diag += _edge_dot(Dt, _apply(S_t, Dt, out=ws("SD", (3, 4, m)), tmp=tmp4), out=edge_tmp)

        # material: the declared tangent pairs
        G_of: Dict[int, np.ndarray] = {}
        for key, slot in self._slots.items():
            w = weights.get(key)
            if w is None or _is_zero(w):
                continue
            if slot.kind == "spectral":
                for wn, yn in _spectral_outers(np.broadcast_to(w, (m, 3, 3)), kin, Dt, ws):
                    outers.append((wn, "cell", yn, "edge"))
                continue
            G = G_of.get(id(slot.MD))  # slots of both kinds with the same M share F M D_a
            if G is None:
                G = G_of[id(slot.MD)] = _apply(Ft, slot.MD, out=ws(slot.name + "G", (3, 4, m)), tmp=tmp4)
            Gw = ws(slot.name + "Gw", (3, 4, m))
            if slot.kind == "first":
                np.multiply(G, 2.0 * w, out=Gw)
                outers.append((Gw, "a", G, "b"))
            else:
                np.multiply(G, w, out=Gw)
                outers.append((Gw, "b", G, "a"))
                scaled.append((np.multiply(slot.DMD, w, out=ws(slot.name + "s", (6, m))), slot.FMFt(Ft, ws)))

        # regularisation (section 2.3): c v_a (x) v_b -> c [(1 - b) v_a (x) v_b + b (v_a . v_b) Id]
        b = np.clip(1.0 - kin.J, 0.0, 1.0) if self.regularize else None
        keep = None if b is None else 1.0 - b

        # g2 d_a (x) d_b, folded into the volumetric coupling d_a (x) F S-hat D_b when present
        dJ = dJ_of() if (g2 is not None or S_hat is not None) else None
        g2_vec = None
        if g2 is not None:
            g2_vec = np.multiply(dJ, g2 if keep is None else g2 * keep, out=ws("g2_vec", (3, 4, m)))
            if b is not None:
                edge_tmp = _edge_dot(dJ, dJ, out=edge_tmp)
                edge_tmp *= g2 * b
                diag += edge_tmp
        if S_hat is not None:
            FSD = self._vector_field(Ft, S_hat, None, None, ws("FSD", (3, 4, m)))
            v = FSD if g2_vec is None else np.add(FSD, g2_vec, out=ws("FSD_g2", (3, 4, m)))
            outers.append((dJ, "a", v, "b"))
            outers.append((FSD, "a", dJ, "b"))
        elif g2_vec is not None:
            outers.append((dJ, "a", g2_vec, "b"))

        # exponential groups: c e^u du (x) du, regularised like g2
        for k, (scale, du) in enumerate(rank_one):
            outers.append((np.multiply(du, scale if keep is None else scale * keep, out=ws(f"du_s{k}", (3, 4, m))),
                           "a", du, "b"))
            if b is not None:
                edge_tmp = _edge_dot(du, du, out=edge_tmp)
                edge_tmp *= scale * b
                diag += edge_tmp

        # h d2J/dx_a dx_b = h eps_rcq (F (D_a x D_b))_q, a skew matrix
        skew = None
        if h is not None:
            skew = _apply(Ft, self._DxD, out=ws("skew", (3, 6, m)), tmp=ws("tmp6", (6, m)))
            skew *= h

        return _sum_components(outers, scaled, diag, skew, self.volumes, out, ws("tmp_3m", (3, m)))


def _edge_dot(u: np.ndarray, v: np.ndarray, out: "np.ndarray | None" = None) -> np.ndarray:
    """u_a . v_b for every edge (a, b) of node vectors u, v (3, 4, m) -> (6, m)."""
    m = u.shape[-1]
    out = np.empty((6, m)) if out is None else out
    tmp = np.empty(m)
    for e, (a, b) in enumerate(EDGES):
        np.multiply(u[0, a], v[0, b], out=out[e])
        for k in (1, 2):
            np.multiply(u[k, a], v[k, b], out=tmp)
            out[e] += tmp
    return out


# Skew part: component (r, c) gets sign * v[q].
_SKEW = {(0, 1): (2, 1.0), (1, 0): (2, -1.0), (0, 2): (1, -1.0), (2, 0): (1, 1.0), (1, 2): (0, 1.0), (2, 1): (0, -1.0)}


# The edges grouped by their first node a: edges e0..e1 are (a, a+1), ..., (a, 3).
_SEGMENTS = ((0, 0, 3), (1, 3, 5), (2, 5, 6))


def _part(x: np.ndarray, where: str, k: int, a: int, e0: int, e1: int) -> np.ndarray:
    """Component k of a vector field on the edges e0..e1 that start at node a, (n, m) or
    broadcastable to it: per node at the edge's first ("a") or second ("b") node, per edge,
    or per cell."""
    if where == "a":
        return x[k, a][None]
    if where == "b":
        return x[k, a + 1:]
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
                    np.multiply(_part(u, uw, r, a, e0, e1), _part(v, vw, c, a, e0, e1), out=t if started else row)
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


class _GroupAggregates:
    """Running sums of one group's terms: u, S-bar, S-hat, h, g2 and the tangent weights.

    Sums that no term feeds stay None, so e.g. St Venant-Kirchhoff (f = 1) never builds the
    volumetric coupling.
    """

    def __init__(self, m: int):
        self.m = m
        self.u = np.zeros(m)
        self.S = None
        self.S_hat = None
        self.h = None
        self.g2 = None
        self.pair_weights: Dict[Tuple[str, object], object] = {}

    def add(self, term, kin, J) -> None:
        f, df, d2f = term.f(J)
        g = term.g.value(kin)
        self.u += f * g
        if not _is_zero(df) and not _is_zero(g):
            self.h = _add(self.h, df * g)
        if not _is_zero(d2f) and not _is_zero(g):
            self.g2 = _add(self.g2, d2f * g)
        Sk = term.g.stress(kin)
        if Sk is not None:
            if not _is_zero(f):
                self.S = _add(self.S, _scale(f, Sk))
            if not _is_zero(df):
                self.S_hat = _add(self.S_hat, _scale(df, Sk))
        for pair, coef in zip(term.g.tangent, term.g.tangent_coefficients(kin)):
            key = _slot_key(pair)
            self.pair_weights[key] = _add(self.pair_weights.get(key), _scale(f, coef))


def _spectral_outers(theta: np.ndarray, kin: Kinematics, Dt: np.ndarray, ws: _Scratch) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Edge blocks of sum_{n,l} theta_nl P_n H P_l, P_n = v_n v_n^T (eigenprojectors of C),
    as three outer products w_n (x) y_n.

    With w_n = F v_n and c_na = v_n . D_a, block (a, b) is
    sum_{n,l} theta_nl [c_nb c_la w_n (x) w_l + c_lb c_la w_n (x) w_n]
    = sum_n w_n (x) y_n,  y_n = c_nb sum_l theta_nl c_la w_l + (sum_l theta_nl c_lb c_la) w_n.

    theta: (m, 3, 3). Returns [(w_n (3, m), y_n (3, 6, m))] for n = 0, 1, 2.
    """
    m = Dt.shape[-1]
    V_t = _soa(kin.eig[1], out=ws("V_t", (3, 3, m)))  # [j, n] = (v_n)_j
    # w[n, i] = (F v_n)_i and c[n, a] = v_n . D_a
    w = np.einsum("ikm,knm->nim", kin.Ft, V_t, out=ws("spec_w", (3, 3, m)))
    c = np.einsum("jnm,jam->nam", V_t, Dt, out=ws("spec_c", (3, 4, m)))
    ca, cb = np.take(c, _EA, axis=1), np.take(c, _EB, axis=1)  # (3, 6, m)
    T = _soa(theta, out=ws("spec_T", (3, 3, m)))
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


def _scale(s, A):
    """s * A with s per cell, (m,) or scalar, and A (m, ...) or scalar."""
    if np.ndim(s) == 0 or np.ndim(A) <= 1:
        return s * A
    return np.reshape(s, np.shape(s) + (1,) * (np.ndim(A) - 1)) * A


def _scale_opt(s, A):
    return None if A is None else _scale(s, A)


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
