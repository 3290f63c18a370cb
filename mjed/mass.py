"""Mass matrices of P1 tetrahedra from a density.

For a linear tetrahedron of rest volume V and density rho, the consistent mass matrix is
rho V / 20 (1 + delta_ab) per pair of nodes (a, b) and per component; its row sums give the
lumped (diagonal) mass rho V / 4 per node and cell. Both are (3n, 3n) CSR with
dof = 3 * node + component, like the stiffness.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mjed.mesh import TetMesh
from mjed.sparse import element_dofs

__all__ = [
    "MASS_KINDS",
    "cell_densities",
    "nodal_masses",
    "lumped_mass",
    "consistent_mass",
    "mass_matrix",
]

MASS_KINDS = ("lumped", "consistent")


def cell_densities(mesh: TetMesh, density) -> np.ndarray:
    """One density per cell, (m,), from a scalar or an (m,) array; finite and >= 0.

    Raises:
        ValueError: naming the parameter and the first bad value.
    """
    rho = np.asarray(density, dtype=np.float64)
    if rho.ndim == 0:
        rho = np.full(mesh.n_cells, float(rho))
    if rho.shape != (mesh.n_cells,):
        raise ValueError(
            f"density must be a scalar or have shape ({mesh.n_cells},), got shape {rho.shape}"
        )
    bad = ~(np.isfinite(rho) & (rho >= 0.0))
    if bad.any():
        c = int(np.flatnonzero(bad)[0])
        raise ValueError(f"density must be finite and >= 0; cell {c} has density={rho[c]!r}")
    return rho


def nodal_masses(mesh: TetMesh, density) -> np.ndarray:
    """Lumped mass of each node, (n,): a quarter of the mass of every cell around it."""
    cell_mass = cell_densities(mesh, density) * mesh.volumes
    return np.bincount(
        mesh.cells.ravel(), weights=np.repeat(cell_mass / 4.0, 4), minlength=mesh.n_nodes
    )


def lumped_mass(mesh: TetMesh, density) -> sp.csr_matrix:
    """Diagonal (row-summed) mass matrix, CSR (3n, 3n)."""
    return sp.diags(np.repeat(nodal_masses(mesh, density), 3), format="csr")


def consistent_mass(mesh: TetMesh, density) -> sp.csr_matrix:
    """Consistent P1 mass matrix, int rho N_a N_b dV times the 3x3 identity, CSR (3n, 3n)."""
    cell_mass = cell_densities(mesh, density) * mesh.volumes  # (m,)
    nodal = (np.ones((4, 4)) + np.eye(4)) / 20.0  # int N_a N_b dV / V on a tetrahedron
    element = np.kron(nodal, np.eye(3))  # (12, 12), dof order (node, component)
    data = cell_mass[:, None, None] * element  # (m, 12, 12)
    dofs = element_dofs(mesh.cells)  # (m, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * mesh.n_nodes
    M = sp.coo_matrix((data.ravel(), (rows, cols)), shape=(n, n)).tocsr()
    M.eliminate_zeros()
    return M


def mass_matrix(mesh: TetMesh, density, kind: str = "lumped") -> sp.csr_matrix:
    """The lumped or the consistent mass matrix, CSR (3n, 3n)."""
    if kind == "lumped":
        return lumped_mass(mesh, density)
    if kind == "consistent":
        return consistent_mass(mesh, density)
    raise ValueError(f"mass must be one of {MASS_KINDS}, got {kind!r}")
