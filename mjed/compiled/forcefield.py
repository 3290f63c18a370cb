"""CompiledForceField: MJED forces and stiffness from the compiled kernel, same API as
:class:`mjed.HyperelasticForceField`.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from mjed.compiled.assembly import CompiledAssembly
from mjed.compiled.availability import require_numba
from mjed.compiled.lowering import lower_groups
from mjed.compiled.shape import kernel_shape
from mjed.compiled.specialise import kernel_module
from mjed.forcefield import check_field_arguments, checked_positions, refuse_inverted
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = ["CompiledForceField", "kernel_positions"]


def kernel_positions(x, n_nodes: int) -> np.ndarray:
    """X checked (mjed.forcefield.checked_positions) and as a C-contiguous, writeable float64
    (n_nodes, 3) array: Numba compiles one specialisation per array layout and per read-only
    flag (each several seconds), so a view or a read-only array from the caller is copied
    rather than handed to a compiled kernel.
    """
    x = checked_positions(x, n_nodes)
    if not (x.flags.c_contiguous and x.flags.writeable):
        x = np.array(x, order="C")
    return x


class CompiledForceField:
    """Nodal forces and tangent stiffness by MJED, one compiled pass over the cells.

    Same conventions and methods as :class:`mjed.HyperelasticForceField`: f = -dW/dx (n, 3),
    K = d2W/dx2 as SciPy CSR (3n, 3n) with the pattern of :class:`mjed.sparse.CSRPattern`,
    dof = 3 node + component. ``backend`` is "numba". Serial (one thread).

    Args:
        mesh: the rest mesh.
        material: one of :mod:`mjed.materials` (its declared terms are lowered once, see
            :mod:`mjed.compiled.lowering`).
        regularize: compressed-element regularisation (paper section 2.3), as the NumPy engine.
        allow_inverted: evaluate states with J <= 0 (NaN where ln J appears) instead of raising.

    Raises:
        BackendUnavailable: Numba is not installed.
        NotImplementedError: the material has a term kind without a compiled form.
    """

    backend = "numba"

    def __init__(
        self,
        mesh: TetMesh,
        material: Material,
        *,
        regularize: bool = False,
        allow_inverted: bool = False,
    ):
        check_field_arguments(mesh, material)
        self._k = require_numba()
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.table = lower_groups(material.decomposition(), mesh.D)
        self.shape = kernel_shape(self.table)
        self._kernel = kernel_module(self.shape).mjed_cells
        self.pattern = CSRPattern(mesh.cells, mesh.n_nodes)
        self._cells = np.ascontiguousarray(mesh.cells, dtype=np.int64)
        self._D = np.ascontiguousarray(mesh.D, dtype=np.float64)
        self._V0 = np.ascontiguousarray(mesh.volumes, dtype=np.float64)
        self._assembly = CompiledAssembly(self.pattern, self._k)
        self._J = np.empty(mesh.n_cells)

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W at positions x (n, 3)."""
        return self._run(x, force=False, stiffness=False)[0]

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3)."""
        return self._run(x, force=True, stiffness=False)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n)."""
        return self._run(x, force=False, stiffness=True)[2]

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both from one pass over the cells."""
        _, f, K, _ = self._run(x, force=True, stiffness=True)
        return f, K

    def stress(self, x) -> np.ndarray:
        """Second Piola-Kirchhoff stress S = 2 dW/dC per cell, (m, 3, 3) (Pa, per unit rest
        volume).
        """
        return self._run(x, force=False, stiffness=False, stress=True)[3]

    def force_stiffness_and_stress(self, x) -> Tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
        """Force (n, 3), stiffness CSR (3n, 3n) and S per cell (m, 3, 3), from one pass."""
        _, f, K, S = self._run(x, force=True, stiffness=True, stress=True)
        return f, K, S

    # ---------------------------------------------------------------- internals
    def _run(self, x, *, force: bool, stiffness: bool, stress: bool = False):
        x = kernel_positions(x, self.mesh.n_nodes)
        t = self.table
        f = np.zeros((self.mesh.n_nodes, 3)) if force else np.zeros((0, 3))
        data = np.zeros(self.pattern.nnz) if stiffness else np.zeros(0)
        S = np.empty((self.mesh.n_cells if stress else 0, 3, 3))
        energy = self._kernel(
            x,
            self._cells,
            self._D,
            self._V0,
            t.jpar,
            t.gpar,
            t.gmat,
            t.group_coef,
            t.slot_M,
            self.regularize,
            force,
            stiffness,
            stress,
            *self._assembly.arguments(),
            f,
            data,
            self._J,
            S,
        )
        if not self.allow_inverted:
            refuse_inverted(self._J)
        return (
            float(energy),
            (f if force else None),
            (self._assembly.matrix(data) if stiffness else None),
            (S if stress else None),
        )
