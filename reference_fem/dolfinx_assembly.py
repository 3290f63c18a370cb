"""dolfinx's compiled assembly of the hyperelastic residual and Jacobian, for timing.

The same forms as the UFL oracle (W from :mod:`reference_fem.energies`, R = dPi/du [v],
K = dR/du [du], quadrature degree 1, exact for P1), compiled once when the object is built.
What a timed call does is only what a Newton step of a dolfinx code does each iteration:
copy the state into u, assemble R into a PETSc vector and K into a PETSc matrix (zeroed
first, finalised with MatAssembly). The results stay in dolfinx's numbering and PETSc
objects: renumbering them to the input order (which the oracle does for comparisons) is not
part of a solver's cost and is excluded. Serial (MPI.COMM_SELF).
"""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np
import ufl

from reference_fem import compat
from reference_fem.energies import strain_energy_density
from reference_fem.numbering import build_mesh, compute_numbering
from reference_fem.ufl_oracle import QUADRATURE_DEGREE
from reference_fem.validation import check_cells, check_points, check_positions

__all__ = ["DolfinxAssembly"]


class DolfinxAssembly:
    """Compiled residual and Jacobian assembly of ``material`` on the mesh (points, cells).

    Args:
        points: (n, 3) rest positions.
        cells: (m, 4) positively oriented P1 tetrahedra.
        material: an mjed material (its type picks W, its attributes are the parameters); Costa only
        with
            a constant frame (the timing study's default).

    Methods ``set_state``, ``assemble_residual``, ``assemble_jacobian`` and
    ``force_and_stiffness`` return the PETSc objects (dolfinx numbering).
    """

    def __init__(self, points, cells, material: Any):
        X = check_points(points)
        cells = check_cells(cells, X)
        frame = getattr(material, "frame", None)
        if frame is not None and np.ndim(frame) == 3:
            raise ValueError(
                "DolfinxAssembly: per-cell Costa frames are not supported; use a constant frame"
            )
        self._X = X
        self.n_nodes, self.n_cells = X.shape[0], cells.shape[0]
        comm = compat.comm_self()
        self.mesh = build_mesh(X, cells, comm)
        self.V = compat.vector_p1_space(self.mesh)
        self._numbering = compute_numbering(self.mesh, self.V, X, cells)
        self._u = compat.function(self.V, "u")
        F = ufl.Identity(3) + ufl.grad(self._u)
        W = strain_energy_density(material, F, constant=lambda v: compat.constant(self.mesh, v))
        dx = ufl.Measure("dx", domain=self.mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})
        R = ufl.derivative(W * dx, self._u, ufl.TestFunction(self.V))
        K = ufl.derivative(R, self._u, ufl.TrialFunction(self.V))
        # timed against the other methods: FFCx's own optimisation, whatever the mesh size
        self._R = compat.compile_form(R, optimise=True)
        self._K = compat.compile_form(K, optimise=True)
        self.b = compat.create_vector(self._R)
        self.A = compat.create_matrix(self._K)
        self._dof_nodes = self._numbering.input_node_of_dof_node

    def set_state(self, x) -> None:
        """U = x - X in dolfinx's dof order; x (n, 3)."""
        x = check_positions(x, self.n_nodes)
        self._u.x.array[:] = (x - self._X)[self._dof_nodes].ravel()

    def assemble_residual(self):
        """R = dPi/du (= -force) into the PETSc vector ``b`` (ghosts accumulated)."""
        compat.assemble_vector_into(self.b, self._R)
        compat.accumulate_ghosts(self.b)
        return self.b

    def assemble_jacobian(self):
        """K = d2Pi/du2 into the PETSc matrix ``A`` (zeroed, assembled, finalised)."""
        compat.assemble_matrix_into(self.A, self._K)
        return self.A

    def force_and_stiffness(self, x) -> Tuple[Any, Any]:
        """One Newton step's assembly: set the state, then R and K (PETSc objects)."""
        self.set_state(x)
        return self.assemble_residual(), self.assemble_jacobian()

    def force(self, x):
        self.set_state(x)
        return self.assemble_residual()

    def stiffness(self, x):
        self.set_state(x)
        return self.assemble_jacobian()
