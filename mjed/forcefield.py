"""HyperelasticForceField: the public face of the engine on one mesh and one material."""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from mjed.engine import MJEDEngine, SoAEvaluation, edge_blocks_to_element_matrices
from mjed.errors import InvertedElementError
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = ["HyperelasticForceField"]


class HyperelasticForceField:
    """Nodal forces and tangent stiffness of a hyperelastic body by MJED.

    Conventions (CONVENTIONS.md): force f = -dW/dx, shape (n, 3); stiffness K = d2W/dx2,
    symmetric, CSR (3n, 3n) with dof = 3 * node + component.

    Args:
        mesh: the rest mesh.
        material: one of :mod:`mjed.materials`.
        regularize: compressed-element regularisation (paper section 2.3); K is then no longer
            the exact Hessian where J < 1.
        allow_inverted: evaluate states with J <= 0 in some cell instead of raising
            InvertedElementError (energies containing ln J are then NaN there).
    """

    def __init__(self, mesh: TetMesh, material: Material, *, regularize: bool = False, allow_inverted: bool = False):
        if not isinstance(mesh, TetMesh):
            raise TypeError(f"mesh must be an mjed.TetMesh, got {type(mesh).__name__}")
        if not isinstance(material, Material):
            raise TypeError(f"material must be an mjed material, got {type(material).__name__}")
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.engine = MJEDEngine(mesh.D, mesh.volumes, material.decomposition(), regularize=self.regularize)
        self._pattern: "CSRPattern | None" = None
        # Scratch for the edge blocks of force_and_stiffness/stiffness, which consume them
        # at once: reusing it saves a fresh 432 bytes per cell (and its page faults) per call.
        self._blocks_buffer: "np.ndarray | None" = None
        self._cells_t: "np.ndarray | None" = None

    @property
    def pattern(self) -> CSRPattern:
        """The CSR pattern and scatter map, built on first use and kept."""
        if self._pattern is None:
            self._pattern = CSRPattern(self.mesh.cells, self.mesh.n_nodes)
        return self._pattern

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W at current positions x (n, 3)."""
        return float(self._evaluate(x, stiffness=False).energy.sum())

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3)."""
        return self._assemble_force(self._evaluate(x, stiffness=False))

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n)."""
        return self._assemble_stiffness(self._evaluate(x, stiffness=True, reuse=True))

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both at once, from a single evaluation of the kinematics."""
        ev = self._evaluate(x, stiffness=True, reuse=True)
        return self._assemble_force(ev), self._assemble_stiffness(ev)

    def element_stiffness(self, x) -> np.ndarray:
        """Element stiffness matrices, (m, 12, 12), dof order (node 0: x, y, z, node 1: ...)."""
        return edge_blocks_to_element_matrices(self._evaluate(x, stiffness=True).public().edge_blocks)

    def element_forces(self, x) -> np.ndarray:
        """Per-cell nodal forces -dW_e/dx_a, (m, 4, 3)."""
        return -np.ascontiguousarray(self._evaluate(x, stiffness=False).public().gradient)

    # ---------------------------------------------------------------- internals
    def _assemble_force(self, ev: SoAEvaluation) -> np.ndarray:
        f = self.pattern.assemble_vector_layout(ev.gradient, "kam")
        return np.negative(f, out=f)

    def _assemble_stiffness(self, ev: SoAEvaluation) -> sp.csr_matrix:
        # Edge blocks only: the node blocks follow from translation invariance (sparse.py).
        return self.pattern.assemble_edge_blocks(ev.blocks, "rcem")

    def _evaluate(self, x, *, stiffness: bool, reuse: bool = False) -> SoAEvaluation:
        x = self._check_positions(x)
        out = None
        if stiffness and reuse:
            if self._blocks_buffer is None:
                self._blocks_buffer = np.empty((3, 3, 6, self.mesh.n_cells))
            out = self._blocks_buffer
        if self._cells_t is None:
            self._cells_t = np.ascontiguousarray(self.mesh.cells.T)
        x_t = np.take(np.ascontiguousarray(x.T), self._cells_t, axis=1)  # (3, 4, m)
        if self.allow_inverted:
            # ln J and J^p are NaN for J <= 0: that is the documented answer, not a surprise.
            with np.errstate(invalid="ignore", divide="ignore"):
                return self.engine.evaluate_soa(x_t, stiffness=stiffness, out=out)
        return self.engine.evaluate_soa(x_t, stiffness=stiffness, check_J=refuse_inverted, out=out)

    def _check_positions(self, x) -> np.ndarray:
        return checked_positions(x, self.mesh.n_nodes)


def checked_positions(x, n_nodes: int) -> np.ndarray:
    """x as float64 (n_nodes, 3), or ValueError naming the shape or the first non-finite node."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n_nodes, 3):
        raise ValueError(f"positions must have shape ({n_nodes}, 3), got {x.shape}")
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{int(bad.sum())} node(s) with non-finite positions; first is node {i}: {x[i].tolist()}")
    return x


def refuse_inverted(J: np.ndarray) -> None:
    bad = np.flatnonzero(~(J > 0))
    if len(bad):
        raise InvertedElementError(bad, J[bad], context="at the given positions")
