"""A dolfinx mesh from (points, cells), and the map between input numbering and dolfinx's.

dolfinx renumbers both: ``create_mesh`` reorders the cells (graph reordering for locality)
and the geometry nodes, and the P1 function space numbers its dofs in yet another order.
With several MPI ranks each rank holds a share of the cells, its owned dof nodes first and
then the ghost ones. The map is recovered from the cell-wise lists, which refer to the same
cell in both:

    V dof node      cell_dofs(V)[c, i]
    geometry node   geometry_dofmap(mesh)[c, i]    (same local vertex i: both are P1)
    input node      input_global_indices(mesh)[geometry node]
    input cell      original_cell_index(mesh)[c]

and then checked against the coordinates, so that an error in this reasoning cannot pass
silently. Release differences in these accessors live in :mod:`reference_fem.compat`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_fem import compat

__all__ = ["Numbering", "build_mesh", "compute_numbering", "NumberingError"]


class NumberingError(ValueError):
    """dolfinx's numbering could not be matched to the input numbering."""


def build_mesh(points: np.ndarray, cells: np.ndarray, comm=None):
    """A dolfinx tetrahedral mesh with a P1 vector coordinate element.

    Args:
        points: (n, 3) float64 rest positions.
        cells: (m, 4) int64 node indices.
        comm: MPI communicator, MPI.COMM_SELF by default. With several ranks the whole
            input is handed to dolfinx on rank 0 (the other ranks' arrays are ignored) and
            dolfinx's partitioner distributes the cells; input indices are then global.
    """
    comm = compat.comm_self() if comm is None else comm
    if comm.rank != 0:
        points, cells = np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    return compat.create_tet_mesh(comm, cells, points)


@dataclass(frozen=True)
class Numbering:
    """Index maps between input numbering and dolfinx's on this rank, for one mesh and P1 space.

    Attributes:
        n_input_nodes: n, number of input points (some may be unused by the cells).
        input_node_of_dof_node: (n_dof_nodes,) input node of each V dof node (block) on
            this rank: the owned ones first, then the ghosts.
        input_cell_of_cell: (m_rank,) input cell of each cell owned by this rank (the
            first m_rank local cells).
        input_dof_of_dof: (3 n_dof_nodes,) scalar index map, 3*node + component.
        n_owned_dof_nodes: how many of the dof nodes this rank owns (all of them in serial).
        owned_offset: global index of this rank's first owned dof node (0 in serial).
    """

    n_input_nodes: int
    input_node_of_dof_node: np.ndarray
    input_cell_of_cell: np.ndarray
    input_dof_of_dof: np.ndarray
    n_owned_dof_nodes: int = -1
    owned_offset: int = 0

    def __post_init__(self):
        if self.n_owned_dof_nodes < 0:  # serial default: this rank owns every dof node
            object.__setattr__(self, "n_owned_dof_nodes", int(self.input_node_of_dof_node.size))

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
    """Per-cell lists (cells on this rank, 4) of geometry nodes and V dof nodes.

    All local cells, owned and ghost: depending on the release's default ghost mode a rank
    may hold ghost cells, whose nodes are among its ghost dof nodes. Assembly integrates
    over owned cells only, so ghost cells are never counted twice.
    """
    geo = compat.geometry_dofmap(mesh)
    dofs = compat.cell_dofs(V, 4)
    if geo.shape != dofs.shape:
        raise NumberingError(
            f"geometry dofmap {geo.shape} and V dofmap {dofs.shape} differ in shape"
        )
    return geo, dofs


def _check_cell_permutation(comm, input_cell_of_cell: np.ndarray, m: int) -> None:
    """The owned cells of all ranks are the input cells, each exactly once."""
    if comm.size == 1:
        every = input_cell_of_cell
    else:  # m int64 per rank at most: small next to the mesh itself
        every = np.concatenate(comm.allgather(input_cell_of_cell))
    if every.shape != (m,) or not np.array_equal(np.sort(every), np.arange(m)):
        raise NumberingError(
            f"original cell indices are not a permutation of the {m} input cells (dolfinx holds "
            f"{every.size} cells)"
        )


def compute_numbering(mesh, V, points: np.ndarray, cells: np.ndarray) -> Numbering:
    """Build and verify the input <-> dolfinx maps for ``mesh`` and its P1 vector space ``V``.

    Collective over ``mesh.comm``; every rank needs the whole input ``points`` (n, 3) and
    ``cells`` (m, 4), against which its share is checked.

    Raises:
        NumberingError: if the maps are inconsistent, the mesh geometry does not equal the
            input points bit for bit (dolfinx copies them), or the dof coordinates differ
            from them by more than rounding.
    """
    if V.dofmap.index_map_bs != 3 or V.dofmap.bs != 3:
        raise NumberingError("expected a P1 vector space with block size 3")
    n, m = points.shape[0], cells.shape[0]
    geo, dofs = _cell_lists(mesh, V)
    input_of_geo = compat.input_global_indices(mesh)
    index_map = V.dofmap.index_map
    start, stop = compat.owned_range(index_map)
    n_owned = stop - start
    n_dof_nodes = n_owned + compat.num_ghosts(index_map)

    all_cells = compat.original_cell_index(mesh)
    if all_cells.shape != (geo.shape[0],):
        raise NumberingError(
            f"{all_cells.size} original cell indices for {geo.shape[0]} local cells"
        )
    input_cell_of_cell = all_cells[: compat.num_owned_cells(mesh)]  # owned cells come first
    _check_cell_permutation(mesh.comm, input_cell_of_cell, m)

    input_node_of_dof_node = np.full(n_dof_nodes, -1, dtype=np.int64)
    input_node_of_dof_node[dofs] = input_of_geo[geo]
    # Every cell must agree (a dof node shared by cells maps to one input node), and with
    # ghost mode none every dof node on a rank belongs to one of its cells.
    if np.any(input_node_of_dof_node < 0) or np.any(
        input_node_of_dof_node[dofs] != input_of_geo[geo]
    ):
        raise NumberingError("V dof nodes and geometry nodes do not correspond one to one")
    if np.unique(input_node_of_dof_node).size != n_dof_nodes:
        raise NumberingError("two V dof nodes map to the same input node")
    if input_node_of_dof_node.max(initial=-1) >= n:
        raise NumberingError("a dof node maps to an input node beyond the input points")

    mapped = np.sort(input_node_of_dof_node[dofs], axis=1)
    if not np.array_equal(mapped, np.sort(cells[all_cells], axis=1)):
        raise NumberingError("cells mapped back through the numbering differ from the input cells")

    # The decisive check: positions seen by dolfinx are exactly the input points.
    if not np.array_equal(mesh.geometry.x[:, :3][geo], points[input_of_geo[geo]]):
        raise NumberingError(
            "mesh geometry does not match the input points through input_global_indices"
        )
    # Dof coordinates are recomputed by pushing the reference vertices forward (sums with
    # 0/1 weights in some order), so they may differ from the points by an ulp or two.
    dof_xyz = compat.dof_coordinates(V)[:n_dof_nodes]
    if n_dof_nodes:
        err = np.abs(dof_xyz - points[input_node_of_dof_node]).max()
        if not err <= 16 * np.finfo(np.float64).eps * max(1.0, np.abs(points).max()):
            raise NumberingError(
                f"dof coordinates differ from the input points (max |diff| = {err:.3g})"
            )

    input_dof_of_dof = (3 * input_node_of_dof_node[:, None] + np.arange(3)).ravel()
    return Numbering(
        n, input_node_of_dof_node, input_cell_of_cell, input_dof_of_dof, n_owned, start
    )
