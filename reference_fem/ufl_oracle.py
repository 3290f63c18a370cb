"""The UFL Galerkin oracle: energy, nodal forces and stiffness of a P1 tetrahedral mesh.

The strain energy W comes from :mod:`reference_fem.energies` (typed from its formula) and
UFL differentiates it: Pi = int W dx, R = dPi/du [v], K = dR/du [du]. With P1 elements F is
constant per cell, so a one-point quadrature (degree 1) is exact. Results are returned in
the input numbering (dof index 3*node + component), with the project's signs:
force = -R and stiffness = K (the Hessian of the total energy).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Any, Optional, Tuple

import numpy as np
import scipy.sparse as sp
import ufl

from reference_fem import compat
from reference_fem.distributed import ROOT, all_finite, collective, gather_csr, gather_rows, on_root
from reference_fem.energies import energy_formula, strain_energy_density
from reference_fem.numbering import Numbering, build_mesh, compute_numbering
from reference_fem.sparse_map import CSRRenumbering
from reference_fem.validation import (
    check_cells,
    check_frame,
    check_points,
    check_positions,
    signed_volumes,
)

__all__ = ["UFLOracle", "QUADRATURE_DEGREE"]

# Exact for P1: the integrand is constant on each cell.
QUADRATURE_DEGREE = 1


def _checked_mesh(points, cells) -> Tuple[np.ndarray, np.ndarray]:
    X = check_points(points)
    return X, check_cells(cells, X)


#: Serial oracles built on the same mesh share its dolfinx mesh, P1 space and numbering (the
#: diagnosis builds hundreds of oracles, one per candidate energy, on a case's one mesh; each
#: would otherwise partition the mesh, build the dofmap and renumber again, about 60 ms). Each
#: oracle keeps its own function u, forms and PETSc objects; nothing here changes a mesh.
_SHARED: "OrderedDict[tuple, tuple]" = OrderedDict()
SHARED_MESHES_KEPT = 8


def _mesh_space_numbering(X: np.ndarray, cells: np.ndarray, comm) -> tuple:
    """(mesh, V, numbering) of the input mesh (X, cells): shared between serial oracles on
    the same points and cells (the last SHARED_MESHES_KEPT meshes), built anew in parallel.
    """
    key = None
    if comm.size == 1:
        key = (X.shape, cells.shape, _digest(X), _digest(cells))
        if key in _SHARED:
            _SHARED.move_to_end(key)
            return _SHARED[key]
    mesh = build_mesh(X, cells, comm)
    V = compat.vector_p1_space(mesh)
    numbering = collective(comm, compute_numbering, mesh, V, X, cells)
    if key is not None:
        _SHARED[key] = (mesh, V, numbering)
        while len(_SHARED) > SHARED_MESHES_KEPT:
            _SHARED.popitem(last=False)
    return mesh, V, numbering


def _digest(a: np.ndarray) -> str:
    return hashlib.blake2b(np.ascontiguousarray(a).tobytes(), digest_size=16).hexdigest()


class UFLOracle:
    """Reference energy, force and stiffness for ``material`` on the mesh (points, cells).

    Args:
        points: (n, 3) rest positions X.
        cells: (m, 4) node indices of positively oriented P1 tetrahedra (input numbering).
        material: an object whose type has a registered UFL energy and whose attributes are
            its parameters (see :func:`reference_fem.energies.register_energy`); a Costa ``frame``
            may be None,
            an orthonormal (3, 3) frame or one per input cell (m, 3, 3).
        comm: MPI communicator; None for a serial oracle (MPI.COMM_SELF). With several
            ranks every rank constructs the oracle with the same material; the input and
            the positions passed to the methods are read on rank 0 only (the other ranks
            may pass None) and broadcast; dolfinx partitions the cells and each rank
            assembles its share. Force and stiffness are gathered on rank 0 in input order;
            the other ranks get None. The energy is returned on every rank.

    The numbering maps are built once, here, and each form is compiled once, when first
    used (:meth:`compile_forms` compiles all three now); each evaluation only sets u = x - X
    and assembles. Every method is collective over ``comm``.
    """

    def __init__(self, points, cells, material: Any, comm=None):
        self._comm = compat.comm_self() if comm is None else comm
        comm = self._comm
        self._X, self._cells = on_root(comm, _checked_mesh, points, cells)
        self._X.setflags(write=False)
        self._cells.setflags(write=False)
        self._material = material
        n = self._X.shape[0]

        self._mesh, self._V, self._numbering = _mesh_space_numbering(self._X, self._cells, comm)

        # Kinematics and energy, then let UFL differentiate.
        self._u = compat.function(self._V, "u")
        F = ufl.Identity(3) + ufl.grad(self._u)
        # Parameters as dolfinx Constants: the generated code is then the same for every
        # parameter set of a material type, so FFCx's cache is hit after the first build.
        W = strain_energy_density(
            material, F, frame=self._cellwise_frame(), constant=self._constant
        )
        dx = ufl.Measure("dx", domain=self._mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})
        Pi = W * dx
        R = ufl.derivative(Pi, self._u, ufl.TestFunction(self._V))
        K = ufl.derivative(R, self._u, ufl.TrialFunction(self._V))
        # The signatures (FFCx's cache keys) are computed first, for all three forms: in UFL
        # 2022.2, compiling Pi alters the DAG shared with R and K, so their signatures would
        # otherwise depend on whether Pi was a cache hit, and FFCx would compile R and K anew.
        for f in (Pi, R, K):
            f.signature()  # cached on the form object
        # Each form is compiled when first assembled: a caller that needs only the force of a
        # candidate energy (the diagnosis rejects most candidates on their force) never pays for
        # its stiffness form, the largest of the three to compile.
        self._ufl_forms = {"Pi": Pi, "R": R, "K": K}
        self._compiled: dict = {}
        self._b = self._A = None  # PETSc vector and matrix, made with their forms (_form)
        # Input dof of each global dof (owned blocks of ranks 0, 1, ... in order), on rank 0.
        n_owned = self._numbering.n_owned_dof_nodes
        self._input_dof_of_global = gather_rows(
            comm, self._numbering.input_dof_of_dof[: 3 * n_owned]
        )
        self._renumber = None
        if self.is_root:
            self._renumber = CSRRenumbering(self._input_dof_of_global, 3 * n)

    # -- compiled forms (each on first use; collective like every evaluation) ---------------
    def compile_forms(self) -> None:
        """Compile energy, force and stiffness now (else each is compiled when first used)."""
        for name in self._ufl_forms:
            self._form(name)

    def _form(self, name: str):
        """The compiled form ``name`` ("Pi", "R" or "K"), compiled on first use together with the
        PETSc vector (R) or matrix (K) that every later assembly reuses.
        """
        if name not in self._compiled:
            form = compat.compile_form(self._ufl_forms[name])
            if name == "R":
                self._b = compat.create_vector(form)
            elif name == "K":
                self._A = compat.create_matrix(form)
            self._compiled[name] = form
        return self._compiled[name]

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
    def comm(self):
        """The MPI communicator the oracle is distributed over."""
        return self._comm

    @property
    def is_root(self) -> bool:
        """True on the rank that receives force and stiffness (rank 0)."""
        return self._comm.rank == ROOT

    @property
    def mesh(self):
        """The dolfinx mesh (dolfinx numbering; this rank's share)."""
        return self._mesh

    @property
    def function_space(self):
        """The P1 vector function space V."""
        return self._V

    @property
    def numbering(self) -> Numbering:
        """Maps between input numbering and V's dofs on this rank."""
        return self._numbering

    # -- evaluations ----------------------------------------------------------------------
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W(F) at current positions ``x`` (n, 3)."""
        xx = self._set_state(x)
        value = compat.assemble_scalar_local(self._form("Pi"))
        if self._comm.size > 1:
            value = float(self._comm.allreduce(value))
        self._require_finite(np.array([value]), "energy", xx)
        return value

    def force(self, x) -> Optional[np.ndarray]:
        """Nodal forces f = -dPi/dx, shape (n, 3), input numbering (None off rank 0)."""
        xx = self._set_state(x)
        return self._assemble_force(xx)

    def stiffness(self, x) -> Optional[sp.csr_matrix]:
        """Stiffness K = d2Pi/dx2 as scipy CSR (3n, 3n), dof index 3*node + component
        (None off rank 0).
        """
        xx = self._set_state(x)
        return self._assemble_stiffness(xx)

    def force_and_stiffness(self, x) -> Tuple[Optional[np.ndarray], Optional[sp.csr_matrix]]:
        """``(force(x), stiffness(x))`` with one state update."""
        xx = self._set_state(x)
        return self._assemble_force(xx), self._assemble_stiffness(xx)

    # -- internals ------------------------------------------------------------------------
    def _constant(self, value):
        """A material parameter (float or (3, 3) array) as a dolfinx Constant."""
        return compat.constant(self._mesh, value)

    def _cellwise_frame(self):
        """A fibre-frame model (Costa, a user energy with I4/I5) with one rotation per cell: a
        DG0 tensor Function holding them; else None (a constant frame is read from the material
        by the energy).
        """
        if not energy_formula(type(self._material)).takes_frame:
            return None
        frame = getattr(self._material, "frame", None)
        if frame is None or np.asarray(frame).shape == (3, 3):
            check_frame(frame, self.n_cells)
            return None
        R = check_frame(frame, self.n_cells)  # (m, 3, 3), input cell order
        Q = compat.tensor_dg0_space(self._mesh)
        Rf = compat.function(Q, "frame")
        m_rank = self._numbering.input_cell_of_cell.size
        block = compat.cell_dofs(Q, 1)[:m_rank, 0]
        # Row-major 3x3 per cell block (UFL's flattening of a rank-2 tensor element).
        Rf.x.array.reshape(-1, 9)[block] = R[self._numbering.input_cell_of_cell].reshape(-1, 9)
        compat.scatter_forward(Rf)
        self._frame_function = Rf  # keep alive with the forms
        return Rf

    def _set_state(self, x) -> np.ndarray:
        """Validate x on rank 0, share it, set u = x - X on this rank's dofs; returns x."""
        xx = on_root(self._comm, check_positions, x, self.n_nodes)
        self._u.x.array[:] = self._numbering.to_dof_order(xx - self._X)
        compat.scatter_forward(self._u)
        return xx

    def _assemble_force(self, x: np.ndarray) -> Optional[np.ndarray]:
        form = self._form("R")  # first: it makes self._b
        compat.assemble_vector_into(self._b, form)
        compat.accumulate_ghosts(self._b)
        owned = self._b.array_r[: 3 * self._numbering.n_owned_dof_nodes].copy()
        self._require_finite(owned, "force", x)
        residual = gather_rows(self._comm, owned)  # global dof order, rank 0 only
        if residual is None:
            return None
        out = np.zeros(3 * self.n_nodes)
        out[self._input_dof_of_global] = residual
        return -out.reshape(-1, 3)

    def _assemble_stiffness(self, x: np.ndarray) -> Optional[sp.csr_matrix]:
        form = self._form("K")  # first: it makes self._A
        compat.assemble_matrix_into(self._A, form)
        indptr, indices, data = self._A.getValuesCSR()  # owned rows, global columns
        self._require_finite(data, "stiffness", x)
        rows = gather_csr(self._comm, indptr, indices, data)
        if rows is None:
            return None
        return self._renumber(*rows)

    def _require_finite(self, values: np.ndarray, what: str, x: np.ndarray) -> None:
        # Collective: every rank raises if any rank saw a non-finite value.
        if all_finite(self._comm, values):
            return
        # Explain the usual cause: inverted or flattened cells (ln J, J^(-2/3), ...).
        vol = signed_volumes(np.asarray(x, dtype=np.float64), self._cells)
        J = vol / signed_volumes(self._X, self._cells)
        bad = np.flatnonzero(J <= 0)
        hint = ""
        if bad.size:
            hint = f"; {bad.size} cell(s) have J <= 0 (first: cell {bad[0]}, J = {J[bad[0]]:.3g})"
        raise ValueError(f"UFL oracle: non-finite {what} for {type(self._material).__name__}{hint}")
