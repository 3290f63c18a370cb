"""A dolfinx mesh from (points, cells), and the map between input numbering and dolfinx's.

dolfinx renumbers both: ``create_mesh`` reorders the cells (graph reordering for locality)
and the geometry nodes, and the P1 function space numbers its dofs in yet another order.
The map is recovered from the cell-wise lists, which refer to the same cell in both:

    V dof node      V.dofmap.list[c, i]
    geometry node   mesh.geometry.dofmap[c, i]    (same local vertex i: both are P1)
    input node      mesh.geometry.input_global_indices[geometry node]
    input cell      mesh.topology.original_cell_index[c]

and then checked against the coordinates, so that an error in this reasoning cannot pass
silently. Serial only (one process owns all cells and nodes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Numbering", "build_mesh", "compute_numbering", "NumberingError"]


class NumberingError(ValueError):
    """dolfinx's numbering could not be matched to the input numbering."""


def build_mesh(points: np.ndarray, cells: np.ndarray, comm=None):
    """A dolfinx tetrahedral mesh with a P1 vector coordinate element.

    Args:
        points: (n, 3) float64 rest positions.
        cells: (m, 4) int64 node indices.
        comm: MPI communicator, MPI.COMM_SELF by default (only serial is supported).
    """
    import ufl
    from dolfinx.mesh import create_mesh
    from mpi4py import MPI

    comm = MPI.COMM_SELF if comm is None else comm
    if comm.size != 1:
        raise NotImplementedError("the oracle's numbering is serial only (comm.size == 1)")
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))
    return create_mesh(comm, cells, points, domain)


@dataclass(frozen=True)
class Numbering:
    """Index maps between input numbering and dolfinx's, for one mesh and P1 space.

    Attributes:
        n_input_nodes: n, number of input points (some may be unused by the cells).
        input_node_of_dof_node: (n_dof_nodes,) input node of each V dof node (block).
        input_cell_of_cell: (m,) input cell of each dolfinx cell.
        input_dof_of_dof: (3 n_dof_nodes,) scalar index map, 3*node + component.
    """

    n_input_nodes: int
    input_node_of_dof_node: np.ndarray
    input_cell_of_cell: np.ndarray
    input_dof_of_dof: np.ndarray

    def to_dof_order(self, values: np.ndarray) -> np.ndarray:
        """(n, 3) nodal values in input order -> flat (3 n_dof_nodes,) in V's dof order."""
        return values[self.input_node_of_dof_node].ravel()

    def to_input_order(self, dof_values: np.ndarray) -> np.ndarray:
        """Flat (3 n_dof_nodes,) values in V's dof order -> (n, 3) in input order.

        Input nodes not used by any cell get zeros.
        """
        out = np.zeros((self.n_input_nodes, 3))
        out[self.input_node_of_dof_node] = dof_values.reshape(-1, 3)
        return out


def _cell_lists(mesh, V) -> tuple:
    """Per-cell lists (m, 4) of geometry nodes and V dof nodes (local cells only)."""
    m = mesh.topology.index_map(mesh.topology.dim).size_local
    geo = mesh.geometry.dofmap.array.reshape(-1, 4)[:m]
    dofs = V.dofmap.list.array.reshape(-1, 4)[:m]
    return geo, dofs


def compute_numbering(mesh, V, points: np.ndarray, cells: np.ndarray) -> Numbering:
    """Build and verify the input <-> dolfinx maps for ``mesh`` and its P1 vector space ``V``.

    Raises:
        NumberingError: if the maps are inconsistent, the mesh geometry does not equal the
            input points bit for bit (dolfinx copies them), or the dof coordinates differ
            from them by more than rounding.
    """
    if V.dofmap.index_map_bs != 3 or V.dofmap.bs != 3:
        raise NumberingError("expected a P1 vector space with block size 3")
    n, m = points.shape[0], cells.shape[0]
    geo, dofs = _cell_lists(mesh, V)
    if geo.shape[0] != m:
        raise NumberingError(f"dolfinx mesh has {geo.shape[0]} cells, input has {m}")
    input_of_geo = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    n_dof_nodes = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts

    input_node_of_dof_node = np.full(n_dof_nodes, -1, dtype=np.int64)
    input_node_of_dof_node[dofs] = input_of_geo[geo]
    # Every cell must agree (a dof node shared by cells maps to one input node).
    if np.any(input_node_of_dof_node < 0) or np.any(input_node_of_dof_node[dofs] != input_of_geo[geo]):
        raise NumberingError("V dof nodes and geometry nodes do not correspond one to one")
    if np.unique(input_node_of_dof_node).size != n_dof_nodes:
        raise NumberingError("two V dof nodes map to the same input node")

    input_cell_of_cell = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)
    if input_cell_of_cell.shape != (m,) or np.unique(input_cell_of_cell).size != m:
        raise NumberingError("original_cell_index is not a permutation of the input cells")
    mapped = np.sort(input_node_of_dof_node[dofs], axis=1)
    if not np.array_equal(mapped, np.sort(cells[input_cell_of_cell], axis=1)):
        raise NumberingError("cells mapped back through the numbering differ from the input cells")

    # The decisive check: positions seen by dolfinx are exactly the input points.
    if not np.array_equal(mesh.geometry.x[:, :3][geo], points[input_of_geo[geo]]):
        raise NumberingError("mesh geometry does not match the input points through input_global_indices")
    # Dof coordinates are recomputed by pushing the reference vertices forward (sums with
    # 0/1 weights in some order), so they may differ from the points by an ulp or two.
    dof_xyz = V.tabulate_dof_coordinates()[:n_dof_nodes]
    err = np.abs(dof_xyz - points[input_node_of_dof_node]).max()
    if not err <= 16 * np.finfo(np.float64).eps * max(1.0, np.abs(points).max()):
        raise NumberingError(f"dof coordinates differ from the input points (max |diff| = {err:.3g})")

    input_dof_of_dof = (3 * input_node_of_dof_node[:, None] + np.arange(3)).ravel()
    return Numbering(n, input_node_of_dof_node, input_cell_of_cell, input_dof_of_dof)
