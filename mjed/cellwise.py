"""Component-major algebra on every cell at once, and the state of the cells at one x.

Arrays here have the cell axis last and contiguous (see :mod:`mjed.layout`): matrices per
cell (3, 3, m), vectors per node (3, 4, m), per edge (3, 6, m), scalars per edge (6, m).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from mjed.kinematics import Kinematics
from mjed.sparse import EDGES
from mjed.workspace import Workspace

__all__ = [
    "apply_matrix",
    "product",
    "edge_dot",
    "is_zero",
    "CellState",
    "stress_node_vectors",
    "first_piola",
    "cell_gradient",
]


def apply_matrix(
    A: np.ndarray, V: np.ndarray, out: Optional[np.ndarray] = None, tmp: Optional[np.ndarray] = None
) -> np.ndarray:
    """A V per cell: A (3, 3, m), V (3, k, m) -> (3, k, m), out[i] = sum_j A[i, j] V[j].

    tmp: optional (k, m) scratch.
    """
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


def product(
    A: np.ndarray, B: np.ndarray, out: np.ndarray, tmp: Optional[np.ndarray] = None
) -> np.ndarray:
    """A B per cell: A, B (3, 3, m) -> out (3, 3, m), entry by entry (faster than einsum here)."""
    if tmp is None:
        tmp = np.empty(A.shape[-1])
    for i in range(3):
        for j in range(3):
            o = out[i, j]
            np.multiply(A[i, 0], B[0, j], out=o)
            for k in (1, 2):
                np.multiply(A[i, k], B[k, j], out=tmp)
                o += tmp
    return out


def edge_dot(u: np.ndarray, v: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
    """u_a . v_b for every edge (a, b) of EDGES, node vectors u, v (3, 4, m) -> (6, m)."""
    m = u.shape[-1]
    out = np.empty((6, m)) if out is None else out
    tmp = np.empty(m)
    for e, (a, b) in enumerate(EDGES):
        np.multiply(u[0, a], v[0, b], out=out[e])
        for k in (1, 2):
            np.multiply(u[k, a], v[k, b], out=tmp)
            out[e] += tmp
    return out


def is_zero(x) -> bool:
    """True for the scalar 0 (a term's f' or g that is identically zero), never for arrays."""
    return np.ndim(x) == 0 and x == 0


class CellState:
    """The cells at one state x, component-major, with what the engine derives from it.

    Args:
        x_t: (3, 4, m) current positions, [k, a] = x_a,k of each cell.
        Dt: (3, 4, m) rest shape vectors D_a.
        ws: the engine's workspace (F, cof F, C and d_a are written into it).

    Attributes:
        Ft: (3, 3, m) F = sum_a x_a (x) D_a. kin: the strain measures (mjed.kinematics).
        J: (m,) det F.
    """

    def __init__(self, x_t: np.ndarray, Dt: np.ndarray, ws: Workspace):
        m = Dt.shape[-1]
        self.Dt, self.ws, self.m = Dt, ws, m
        # F_ij = sum_a x_a,i D_a,j, formed component-major (the (m, 3, 3) copy only on demand).
        self.Ft = np.einsum("iam,jam->ijm", x_t, Dt, out=ws("Ft", (3, 3, m)))
        self.kin = Kinematics(
            Ft=self.Ft, cof_out=ws("cof_t", (3, 3, m)), C_out=ws("C_t", (3, 3, m))
        )
        self.J = self.kin.J
        self._dJ: Optional[np.ndarray] = None

    @property
    def F(self) -> np.ndarray:
        """(m, 3, 3) F."""
        return self.kin.F

    def dJ(self) -> np.ndarray:
        """d_a = dJ/dx_a = cof(F) D_a, (3, 4, m), formed on first use (St Venant-Kirchhoff
        never needs it).
        """
        if self._dJ is None:
            self._dJ = apply_matrix(
                self.kin.cof_t,
                self.Dt,
                out=self.ws("dJ", (3, 4, self.m)),
                tmp=self.ws("tmp4", (4, self.m)),
            )
        return self._dJ


def stress_node_vectors(state: CellState, S, h, out: np.ndarray) -> np.ndarray:
    """F S D_a + h d_a for every node a of every cell, written into ``out`` (3, 4, m).

    S: component-major (3, 3, m), a (3, 3) constant, or None for zero; h: (m,) or None for
    zero. This is dW/dx_a of a group's aggregates (paper, eqs. 3-4) before the rest volume.
    """
    ws, Dt, m = state.ws, state.Dt, state.m
    if S is None:
        out.fill(0.0)
    else:
        FS = first_piola(state, S, None, ws("FS", (3, 3, m)))
        apply_matrix(FS, Dt, out=out, tmp=ws("tmp4", (4, m)))
    if h is not None:
        tmp = ws("tmp34", (3, 4, m))
        np.multiply(state.dJ(), h, out=tmp)
        out += tmp
    return out


def first_piola(state: CellState, S, h, out: np.ndarray) -> np.ndarray:
    """P = F S + h cof(F) per cell (the first Piola-Kirchhoff stress of the folded groups:
    dW/dx_a = P D_a since d_a = cof(F) D_a), written into ``out`` (3, 3, m).

    S: component-major (3, 3, m), a (3, 3) constant, or None for zero; h: (m,) or None.
    """
    ws, m = state.ws, state.m
    if S is None:
        out.fill(0.0)
    elif np.ndim(S) == 2:  # the same S in every cell: P[i] = S^T F[i] is a (3, 3) x (3, m) product
        np.matmul(np.transpose(S), state.Ft, out=out)
    else:
        product(state.Ft, S, out=out, tmp=ws("tmp_m", (m,)))
    if h is not None:
        tmp = ws("tmp33", (3, 3, m))
        np.multiply(state.kin.cof_t, h, out=tmp)
        out += tmp
    return out


def cell_gradient(state: CellState, S, h, DtV: np.ndarray, out: np.ndarray) -> np.ndarray:
    """V0 dW/dx_a = P (V0 D_a) for every node of every cell, written into ``out`` (3, 4, m);
    P from :func:`first_piola`, DtV (3, 4, m) the rest shape vectors times the rest volumes.
    One 3x3 product per node, the least work for the force alone.
    """
    m = state.m
    P = first_piola(state, S, h, state.ws("P", (3, 3, m)))
    # Nodes 1..3 by the product; node 0 as minus their sum, since sum_a D_a = 0 (a P1 cell's
    # shape gradients sum to zero): a quarter fewer products, and each cell's forces balance
    # exactly (translation invariance holds cell by cell, not only to round-off).
    apply_matrix(P, DtV[:, 1:], out=out[:, 1:], tmp=state.ws("tmp3", (3, m)))
    np.add(out[:, 1], out[:, 2], out=out[:, 0])
    out[:, 0] += out[:, 3]
    np.negative(out[:, 0], out=out[:, 0])
    return out
