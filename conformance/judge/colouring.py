"""Groups of nodes that share no cell: perturbing one dof of each node of a group at once changes
each of their stiffness columns exactly as perturbing it alone would.

Column j of the assembled stiffness sums the element matrices of the cells holding dof j's node;
each of those depends only on its own four nodes. If no other perturbed node lies in any of
those cells, column j at the jointly perturbed positions is, bit for bit, column j at the
positions with dof j alone perturbed (the same cells, the same values, added in the same cell
order). A mesh's nodes need about as many such groups as a node has neighbours (15 to 30 for
tetrahedra), not one group per dof.
"""

from __future__ import annotations

from typing import List

import numpy as np
import scipy.sparse as sp


def independent_node_groups(cells: np.ndarray, n_nodes: int) -> List[np.ndarray]:
    """Nodes in groups of which no two share a cell (a greedy colouring of the graph of nodes
    joined when they share a cell), in node order within each group.

    cells: (m, k) node indices. Returns a list of int64 arrays covering range(n_nodes) once.
    """
    cells = np.asarray(cells, dtype=np.int64)
    m, k = cells.shape
    incidence = sp.csr_matrix(
        (np.ones(m * k), (np.repeat(np.arange(m), k), cells.ravel())), shape=(m, n_nodes)
    )
    adjacency = (incidence.T @ incidence).tocsr()
    colour = np.full(n_nodes, -1, dtype=np.int64)
    # Greedy, node by node: a sequential rule by nature, run only for the small meshes whose
    # stiffness columns the diagnosis differentiates (hundreds of nodes).
    for node in range(n_nodes):
        taken = colour[adjacency.indices[adjacency.indptr[node] : adjacency.indptr[node + 1]]]
        free = np.setdiff1d(np.arange(taken.size + 1), taken, assume_unique=False)
        colour[node] = free[0]
    return [np.flatnonzero(colour == c) for c in range(int(colour.max()) + 1 if n_nodes else 0)]
