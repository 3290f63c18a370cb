"""The UFL Galerkin oracle: energy, nodal forces and stiffness of a P1 tetrahedral mesh.

The strain energy W comes from :mod:`reference_fem.energies` (typed from its formula) and
UFL differentiates it: Pi = int W dx, R = dPi/du [v], K = dR/du [du]. With P1 elements F is
constant per cell, so a one-point quadrature (degree 1) is exact. Results are returned in
the input numbering (dof index 3*node + component), with the project's signs:
force = -R and stiffness = K (the Hessian of the total energy).
"""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np
import scipy.sparse as sp

import dolfinx.fem as fem
import dolfinx.fem.petsc as fem_petsc
import ufl

from reference_fem.energies import strain_energy_density
from reference_fem.numbering import Numbering, build_mesh, compute_numbering
from reference_fem.sparse_map import CSRRenumbering
from reference_fem.validation import check_cells, check_frame, check_points, check_positions, signed_volumes

__all__ = ["UFLOracle", "QUADRATURE_DEGREE"]

# Exact for P1: the integrand is constant on each cell.
QUADRATURE_DEGREE = 1


class UFLOracle:
    """Reference energy, force and stiffness for ``material`` on the mesh (points, cells).

    Args:
        points: (n, 3) rest positions X.
        cells: (m, 4) node indices of positively oriented P1 tetrahedra (input numbering).
        material: object whose class name and attributes give the energy (see
            :func:`reference_fem.strain_energy_density`); a Costa ``frame`` may be None,
            an orthonormal (3, 3) frame or one per input cell (m, 3, 3).

    The forms are compiled and the numbering maps built once, here; each evaluation only
    sets u = x - X and assembles. Serial only.
    """

    def __init__(self, points, cells, material: Any):
        self._X = check_points(points)
        self._cells = check_cells(cells, self._X)
        self._X.setflags(write=False)
        self._cells.setflags(write=False)
        self._material = material
        n = self._X.shape[0]

        self._mesh = build_mesh(self._X, self._cells)
        self._V = fem.VectorFunctionSpace(self._mesh, ("Lagrange", 1))
        self._numbering = compute_numbering(self._mesh, self._V, self._X, self._cells)

        # Kinematics and energy, then let UFL differentiate.
        self._u = fem.Function(self._V, name="u")
        F = ufl.Identity(3) + ufl.grad(self._u)
        # Parameters as dolfinx Constants: the generated code is then the same for every
        # parameter set of a material type, so FFCx's cache is hit after the first build.
        W = strain_energy_density(material, F, frame=self._cellwise_frame(), constant=self._constant)
        dx = ufl.Measure("dx", domain=self._mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})
        Pi = W * dx
        R = ufl.derivative(Pi, self._u, ufl.TestFunction(self._V))
        K = ufl.derivative(R, self._u, ufl.TrialFunction(self._V))
        # The signatures (FFCx's cache keys) are computed first, for all three forms: in UFL
        # 2022.2, compiling Pi alters the DAG shared with R and K, so their signatures would
        # otherwise depend on whether Pi was a cache hit, and FFCx would compile R and K anew.
        for f in (Pi, R, K):
            f.signature()  # cached on the form object
        self._Pi, self._R, self._K = fem.form(Pi), fem.form(R), fem.form(K)

        # PETSc objects reused by every call (zeroed before each assembly).
        self._b = fem_petsc.create_vector(self._R)
        self._A = fem_petsc.create_matrix(self._K)
        self._renumber = CSRRenumbering(self._numbering.input_dof_of_dof, 3 * n)

    # -- properties ---------------------------------------------------------------------
    @property
    def points(self) -> np.ndarray:
        """(n, 3) rest positions (read-only)."""
        return self._X

    @property
    def cells(self) -> np.ndarray:
        """(m, 4) cells in input numbering (read-only)."""
        return self._cells

    @property
    def material(self) -> Any:
        return self._material

    @property
    def n_nodes(self) -> int:
        return self._X.shape[0]

    @property
    def n_cells(self) -> int:
        return self._cells.shape[0]

    @property
    def mesh(self):
        """The dolfinx mesh (dolfinx numbering)."""
        return self._mesh

    @property
    def function_space(self):
        """The P1 vector function space V."""
        return self._V

    @property
    def numbering(self) -> Numbering:
        """Maps between input numbering and V's dofs."""
        return self._numbering

    # -- evaluations ----------------------------------------------------------------------
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W(F) at current positions ``x`` (n, 3)."""
        self._set_state(x)
        value = float(fem.assemble_scalar(self._Pi))
        self._require_finite(np.array([value]), "energy", x)
        return value

    def force(self, x) -> np.ndarray:
        """Nodal forces f = -dPi/dx, shape (n, 3), input numbering."""
        self._set_state(x)
        return self._assemble_force(x)

    def stiffness(self, x) -> sp.csr_matrix:
        """Stiffness K = d2Pi/dx2 as scipy CSR (3n, 3n), dof index 3*node + component."""
        self._set_state(x)
        return self._assemble_stiffness(x)

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """``(force(x), stiffness(x))`` with one state update."""
        self._set_state(x)
        return self._assemble_force(x), self._assemble_stiffness(x)

    # -- internals ------------------------------------------------------------------------
    def _constant(self, value) -> fem.Constant:
        """A material parameter (float or (3, 3) array) as a dolfinx Constant."""
        return fem.Constant(self._mesh, np.asarray(value, dtype=np.float64))

    def _cellwise_frame(self):
        """Costa with one rotation per cell: a DG0 tensor Function holding them; else None
        (a constant frame is read from the material by the energy itself)."""
        if type(self._material).__name__ != "Costa":
            return None
        frame = getattr(self._material, "frame", None)
        if frame is None or np.asarray(frame).shape == (3, 3):
            check_frame(frame, self.n_cells)
            return None
        R = check_frame(frame, self.n_cells)  # (m, 3, 3), input cell order
        Q = fem.TensorFunctionSpace(self._mesh, ("DG", 0))
        Rf = fem.Function(Q, name="frame")
        block = Q.dofmap.list.array.reshape(self.n_cells, 1)[:, 0]
        # Row-major 3x3 per cell block (UFL's flattening of a rank-2 tensor element).
        Rf.x.array.reshape(-1, 9)[block] = R[self._numbering.input_cell_of_cell].reshape(-1, 9)
        Rf.x.scatter_forward()
        self._frame_function = Rf  # keep alive with the forms
        return Rf

    def _set_state(self, x) -> None:
        xx = check_positions(x, self.n_nodes)
        self._u.x.array[:] = self._numbering.to_dof_order(xx - self._X)
        self._u.x.scatter_forward()

    def _assemble_force(self, x) -> np.ndarray:
        with self._b.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(self._b, self._R)
        residual = self._b.array_r.copy()
        self._require_finite(residual, "force", x)
        return -self._numbering.to_input_order(residual)

    def _assemble_stiffness(self, x) -> sp.csr_matrix:
        self._A.zeroEntries()
        fem_petsc.assemble_matrix(self._A, self._K)
        self._A.assemble()
        indptr, indices, data = self._A.getValuesCSR()
        self._require_finite(data, "stiffness", x)
        return self._renumber(indptr, indices, data)

    def _require_finite(self, values: np.ndarray, what: str, x) -> None:
        if np.all(np.isfinite(values)):
            return
        # Explain the usual cause: inverted or flattened cells (ln J, J^(-2/3), ...).
        vol = signed_volumes(np.asarray(x, dtype=np.float64), self._cells)
        J = vol / signed_volumes(self._X, self._cells)
        bad = np.flatnonzero(J <= 0)
        hint = ""
        if bad.size:
            hint = f"; {bad.size} cell(s) have J <= 0 (first: cell {bad[0]}, J = {J[bad[0]]:.3g})"
        raise ValueError(f"UFL oracle: non-finite {what} for {type(self._material).__name__}{hint}")
