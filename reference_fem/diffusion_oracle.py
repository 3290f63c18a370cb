"""The UFL oracle of the Darcy pressure step: P1 mass and stiffness (Laplacian) matrices.

Both come from their weak forms, assembled by dolfinx with an exact quadrature (degree 2
for the mass, whose integrand is quadratic on a P1 tetrahedron):

    M_ij = int N_i N_j dX,        L_ij = int grad N_i . grad N_j dX,

on the rest mesh, then mapped to the input node numbering. Nothing here imports mjed.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from reference_fem import compat
from reference_fem.numbering import NumberingError, build_mesh
from reference_fem.sparse_map import CSRRenumbering
from reference_fem.validation import check_cells, check_points

__all__ = ["scalar_input_node_of_dof", "diffusion_matrices"]


def scalar_input_node_of_dof(mesh, Q, points: np.ndarray) -> np.ndarray:
    """Input node of each dof of a scalar P1 space ``Q`` on ``mesh`` (built by build_mesh).

    The same cell-wise reasoning as :func:`reference_fem.numbering.compute_numbering`, for
    block size 1, checked against the dof coordinates.

    Returns:
        (n_dofs,) int64.
    """
    m = compat.num_owned_cells(mesh)
    geo = compat.geometry_dofmap(mesh)[:m]
    dofs = compat.cell_dofs(Q, 4)[:m]
    input_of_geo = compat.input_global_indices(mesh)
    lo, hi = compat.owned_range(Q.dofmap.index_map)
    n_dofs = (hi - lo) + compat.num_ghosts(Q.dofmap.index_map)
    node = np.full(n_dofs, -1, dtype=np.int64)
    node[dofs] = input_of_geo[geo]
    if (
        np.any(node < 0)
        or np.any(node[dofs] != input_of_geo[geo])
        or np.unique(node).size != n_dofs
    ):
        raise NumberingError("scalar P1 dofs and geometry nodes do not correspond one to one")
    err = np.abs(compat.dof_coordinates(Q)[:n_dofs] - points[node]).max()
    if not err <= 16 * np.finfo(np.float64).eps * max(1.0, np.abs(points).max()):
        raise NumberingError(
            f"scalar dof coordinates differ from the input points (max |diff| = {err:.3g})"
        )
    return node


def _assemble(form, renumber: CSRRenumbering) -> sp.csr_matrix:
    compiled = compat.compile_form(form)
    A = compat.create_matrix(compiled)
    compat.assemble_matrix_into(A, compiled)
    indptr, indices, data = A.getValuesCSR()
    return renumber(indptr, indices, data)


def diffusion_matrices(points, cells) -> Tuple[sp.csr_matrix, sp.csr_matrix]:
    """P1 mass M and stiffness L on the rest mesh, CSR (n, n) in input node order.

    Input nodes used by no cell get empty rows and columns. Serial only.
    """
    X = check_points(points)
    T = check_cells(cells, X)
    import ufl

    mesh = build_mesh(X, T)
    Q = compat.scalar_p1_space(mesh)
    renumber = CSRRenumbering(scalar_input_node_of_dof(mesh, Q, X), len(X))
    p, q = ufl.TrialFunction(Q), ufl.TestFunction(Q)
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 2})
    return _assemble(p * q * dx, renumber), _assemble(
        ufl.inner(ufl.grad(p), ufl.grad(q)) * dx, renumber
    )
