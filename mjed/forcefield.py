"""HyperelasticForceField: the public face of the engine on one mesh and one material."""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from mjed.edge_blocks import edge_blocks_to_element_matrices
from mjed.engine import MJEDEngine
from mjed.errors import InvertedElementError
from mjed.evaluation import CellEvaluation, Want
from mjed.layout import BlockLayout, VectorLayout
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = [
    "HyperelasticForceField",
    "Want",
    "check_field_arguments",
    "checked_positions",
    "refuse_inverted",
]


class HyperelasticForceField:
    """Nodal forces and tangent stiffness of a hyperelastic body by MJED.

    Conventions: force f = -dW/dx, shape (n, 3); stiffness K = d2W/dx2, symmetric, CSR
    (3n, 3n) with dof = 3 * node + component.

    Besides force, stiffness and energy, the field offers a seam for models built on it (a
    viscous history, a compiled backend): :meth:`evaluate` gives the per-cell quantities
    (component-major :class:`mjed.evaluation.CellEvaluation`), which such a model may
    change before :meth:`assemble_force` and :meth:`assemble_stiffness` sum them.

    Args:
        mesh: the rest mesh.
        material: one of :mod:`mjed.materials`.
        regularize: compressed-element regularisation (paper section 2.3); K is then no longer
            the exact Hessian where J < 1.
        allow_inverted: evaluate states with J <= 0 in some cell instead of raising
            InvertedElementError (energies containing ln J are then NaN there).
    """

    #: Which implementation this is (mjed.make_force_field chooses between backends).
    backend = "numpy"

    def __init__(
        self,
        mesh: TetMesh,
        material: Material,
        *,
        regularize: bool = False,
        allow_inverted: bool = False,
    ):
        check_field_arguments(mesh, material)
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.engine = MJEDEngine(
            mesh.D, mesh.volumes, material.decomposition(), regularize=self.regularize
        )
        self._pattern: "CSRPattern | None" = None
        # Scratch for the edge blocks of force_and_stiffness/stiffness, which consume them
        # at once: reusing it saves a fresh 432 bytes per cell (and its page faults) per call.
        self._blocks_buffer: "np.ndarray | None" = None
        # Cells transposed (4, m), to gather positions straight into the engine's layout.
        self._cells_t = np.ascontiguousarray(mesh.cells.T)

    @property
    def pattern(self) -> CSRPattern:
        """The CSR pattern and scatter map, built on first use and kept."""
        if self._pattern is None:
            self._pattern = CSRPattern(self.mesh.cells, self.mesh.n_nodes)
        return self._pattern

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W at current positions x (n, 3)."""
        return float(self.evaluate(x, want=Want.ENERGY).energy.sum())

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3)."""
        return self.assemble_force(self.evaluate(x, want=Want.GRADIENT).gradient)

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n)."""
        return self.assemble_stiffness(
            self.evaluate(x, want=Want.STIFFNESS, out=self._reused_blocks()).blocks
        )

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both at once, from a single evaluation of the kinematics."""
        ev = self.evaluate(x, want=Want.GRADIENT | Want.STIFFNESS, out=self._reused_blocks())
        return self.assemble_force(ev.gradient), self.assemble_stiffness(ev.blocks)

    def stress(self, x) -> np.ndarray:
        """Second Piola-Kirchhoff stress S = 2 dW/dC per cell, (m, 3, 3) (Pa, per unit rest
        volume).
        """
        return self.evaluate(x, want=Want.STRESS).pk2

    def force_stiffness_and_stress(self, x) -> Tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
        """Force (n, 3), stiffness CSR (3n, 3n) and S per cell (m, 3, 3), from one evaluation
        (what a stress-history model needs when it accepts a step).
        """
        ev = self.evaluate(
            x, want=Want.GRADIENT | Want.STIFFNESS | Want.STRESS, out=self._reused_blocks()
        )
        return self.assemble_force(ev.gradient), self.assemble_stiffness(ev.blocks), ev.pk2

    def element_stiffness(self, x) -> np.ndarray:
        """Element stiffness matrices, (m, 12, 12), dof order (node 0: x, y, z, node 1: ...)."""
        return edge_blocks_to_element_matrices(
            self.evaluate(x, want=Want.STIFFNESS).public().edge_blocks
        )

    def element_forces(self, x) -> np.ndarray:
        """Per-cell nodal forces -dW_e/dx_a, (m, 4, 3)."""
        return -np.ascontiguousarray(self.evaluate(x, want=Want.GRADIENT).public().gradient)

    # ---------------------------------------------------------------- the seam
    def evaluate(
        self, x, *, want: Want = Want.ENERGY | Want.GRADIENT, out: "np.ndarray | None" = None
    ) -> CellEvaluation:
        """The per-cell quantities ``want`` names at positions x, component-major.

        Args:
            x: (n, 3) current positions; refused (ValueError) if of the wrong shape or not
                finite.
            want: a combination of :class:`mjed.evaluation.Want` flags.
            out: optional (3, 3, 6, m) float64 array for the edge blocks; without it every
                returned array is fresh (a caller may keep the evaluation).

        Raises:
            InvertedElementError: a cell has J <= 0 (unless the field allows inverted cells;
                energies containing ln J are then NaN there).
        """
        x = checked_positions(x, self.mesh.n_nodes)
        x_t = np.take(np.ascontiguousarray(x.T), self._cells_t, axis=1)  # (3, 4, m)
        if self.allow_inverted:
            # ln J and J^p are NaN for J <= 0: that is the documented answer, not a surprise.
            with np.errstate(invalid="ignore", divide="ignore"):
                return self.engine.evaluate_soa(x_t, want=want, out=out)
        return self.engine.evaluate_soa(x_t, want=want, check_J=refuse_inverted, out=out)

    def assemble_force(self, gradient: np.ndarray) -> np.ndarray:
        """Nodal forces f = -sum_cells gradient, (n, 3), from a (3, 4, m) per-cell gradient
        ([k, a, cell] = dW_cell/dx_a,k, the layout of CellEvaluation.gradient).
        """
        f = self.pattern.assemble_vector_layout(gradient, VectorLayout.COMPONENT_MAJOR)
        return np.negative(f, out=f)

    def assemble_stiffness(self, blocks: np.ndarray) -> sp.csr_matrix:
        """CSR (3n, 3n) sum of (3, 3, 6, m) per-cell edge blocks (the layout of
        CellEvaluation.blocks); the node blocks follow from translation invariance.
        """
        return self.pattern.assemble_edge_blocks(blocks, BlockLayout.COMPONENT_MAJOR)

    # ---------------------------------------------------------------- internals
    def _reused_blocks(self) -> np.ndarray:
        """The edge-block buffer of the calls that assemble the blocks at once."""
        if self._blocks_buffer is None:
            self._blocks_buffer = np.empty((3, 3, 6, self.mesh.n_cells))
        return self._blocks_buffer


def check_field_arguments(mesh, material) -> None:
    """TypeError unless mesh is an mjed.TetMesh and material an mjed material (every backend's
    force field checks its arguments so).
    """
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be an mjed.TetMesh, got {type(mesh).__name__}")
    if not isinstance(material, Material):
        raise TypeError(f"material must be an mjed material, got {type(material).__name__}")


def checked_positions(x, n_nodes: int) -> np.ndarray:
    """X as float64 (n_nodes, 3), or ValueError naming the shape or the first non-finite node."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n_nodes, 3):
        raise ValueError(f"positions must have shape ({n_nodes}, 3), got {x.shape}")
    if np.isfinite(
        x.sum()
    ):  # every entry finite (a NaN or inf would make the sum so): the common case
        return x
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{int(bad.sum())} node(s) with non-finite positions; first is node {i}: "
            f"{x[i].tolist()}"
        )
    return x


def refuse_inverted(J: np.ndarray) -> None:
    """Raise InvertedElementError listing the cells with J <= 0 (or NaN)."""
    bad = np.flatnonzero(~(J > 0))
    if len(bad):
        raise InvertedElementError(bad, J[bad], context="at the given positions")
