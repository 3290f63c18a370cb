"""The generic MJED engine: a material's term groups in, per-cell forces and edge blocks out.

One evaluation runs four concerns, each in its own module::

    mjed.cellwise     the cells at x: F, its strain measures, d_a = cof(F) D_a, F S D_a + h d_a
    mjed.aggregates   the term groups folded into one record (S-bar, S-hat, h, g2, weights)
    mjed.edge_blocks  the six 3x3 edge blocks from that record
    mjed.workspace    the work arrays reused between calls

and returns a :class:`mjed.evaluation.CellEvaluation`.

Layout (why it is fast): the 3x3 algebra runs on component-major arrays whose cell axis is
last and contiguous (mjed.layout): every NumPy operation then streams long contiguous rows
instead of broadcasting over tiny 3x3 trailing axes (about 15x faster for the outer
products). The cell-major :class:`mjed.evaluation.Evaluation` exposes the same arrays as views.
"""

from __future__ import annotations

from typing import Callable, Optional, Tuple

import numpy as np

from mjed.aggregates import fold_groups
from mjed.cellwise import CellState, cell_gradient, stress_node_vectors
from mjed.edge_blocks import (
    MeshConstants,
    edge_blocks,
    edge_blocks_to_element_matrices,
    tangent_slots,
)
from mjed.evaluation import CellEvaluation, Evaluation, Want
from mjed.layout import to_component_major
from mjed.sparse import EDGES
from mjed.terms import TermGroup
from mjed.workspace import Workspace

__all__ = [
    "EDGES",
    "MJEDEngine",
    "Evaluation",
    "CellEvaluation",
    "Want",
    "edge_blocks_to_element_matrices",
]

#: What an evaluation computes unless told otherwise.
DEFAULT_WANT = Want.ENERGY | Want.GRADIENT | Want.STIFFNESS


class MJEDEngine:
    """Evaluates a material's term groups on every cell of a mesh at once.

    Args:
        D: (m, 4, 3) rest shape vectors.
        volumes: (m,) rest volumes.
        groups: the material's term groups.
        regularize: apply the compressed-element regularisation of the paper's section 2.3.

    Work arrays are kept between calls (mjed.workspace): do not evaluate one engine from two
    threads at once.
    """

    def __init__(
        self,
        D: np.ndarray,
        volumes: np.ndarray,
        groups: Tuple[TermGroup, ...],
        *,
        regularize: bool = False,
    ):
        self.D = D
        self.volumes = volumes
        self.groups = groups
        self.regularize = regularize
        # Per-mesh constants, component-major: D (3, 4, m) and D_a x D_b (3, 6, m).
        Dt = np.ascontiguousarray(D.transpose(2, 1, 0))
        DxD = to_component_major(np.cross(D[:, EDGES[:, 0]], D[:, EDGES[:, 1]]).transpose(0, 2, 1))
        self.constants = MeshConstants(Dt, DxD, volumes, tangent_slots(groups, Dt), Dt * volumes)
        self.workspace = Workspace()

    @property
    def n_cells(self) -> int:
        return len(self.D)

    def evaluate(
        self,
        x_cells: np.ndarray,
        *,
        want: Want = DEFAULT_WANT,
        check_J: Optional[Callable[[np.ndarray], None]] = None,
    ) -> Evaluation:
        """The quantities ``want`` names for every cell, cell-major (views of the engine's
        component-major arrays).

        Args:
            x_cells: (m, 4, 3) current positions of each cell's nodes.
            want: see :class:`mjed.evaluation.Want`.
            check_J: called with J (m,) before any material function is evaluated, so a
                caller can refuse inverted cells before ln J or J^p produce NaN.
        """
        x_t = np.ascontiguousarray(np.asarray(x_cells, dtype=np.float64).transpose(2, 1, 0))
        return self.evaluate_soa(x_t, want=want, check_J=check_J).public()

    def evaluate_soa(
        self,
        x_t: np.ndarray,
        *,
        want: Want = DEFAULT_WANT,
        check_J: Optional[Callable[[np.ndarray], None]] = None,
        out: Optional[np.ndarray] = None,
    ) -> CellEvaluation:
        """As :meth:`evaluate`, in component-major layout.

        Args:
            x_t: (3, 4, m) current positions, [k, a] = x_a,k of each cell (contiguous).
            want: as for :meth:`evaluate`.
            check_J: as for :meth:`evaluate`.
            out: optional (3, 3, 6, m) float64 array the edge blocks are written to (a caller
                that consumes the blocks at once can reuse one buffer between calls).
        """
        const, ws = self.constants, self.workspace
        m = self.n_cells
        state = CellState(x_t, const.Dt, ws)
        if check_J is not None:
            check_J(state.J)
        stiffness = bool(want & Want.STIFFNESS)
        du_of = None
        if stiffness:
            # noqa: E731
            du_of = lambda S, h, k: stress_node_vectors(state, S, h, ws(f"du{k}", (3, 4, m)))
        agg = fold_groups(self.groups, state.kin, state.J, du_of, energy=bool(want & Want.ENERGY))

        V0 = self.volumes
        gradient = None
        if want & Want.GRADIENT:
            gradient = cell_gradient(state, agg.S, agg.h, const.DtV, np.empty((3, 4, m)))
        blocks = None
        if stiffness:
            blocks = edge_blocks(const, state, agg, regularize=self.regularize, ws=ws, out=out)
        pk2 = F = None
        if want & Want.STRESS:
            pk2, F = self._pk2(state, agg), state.F
        energy = agg.energy * V0 if want & Want.ENERGY else None
        return CellEvaluation(energy, gradient, blocks, state.J, F, pk2)

    @staticmethod
    def _pk2(state: CellState, agg) -> np.ndarray:
        """S = sum c f_k S_k + h J C^-1, (m, 3, 3); dJ/dC = J C^-1 / 2 and J C^-1 = cof^T cof /
        J.
        """
        m = state.m
        if agg.S is None:
            S = np.zeros((m, 3, 3))
        elif np.ndim(agg.S) == 2:
            S = np.array(np.broadcast_to(agg.S, (m, 3, 3)))
        else:
            S = np.ascontiguousarray(np.moveaxis(agg.S, -1, 0))
        if agg.h is not None:
            cof_t = state.kin.cof_t
            S += (agg.h / state.J)[:, None, None] * np.moveaxis(
                np.einsum("kim,kjm->ijm", cof_t, cof_t), -1, 0
            )
        return S
