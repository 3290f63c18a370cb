"""What a format reader returns before the tetrahedra are picked out."""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Tuple

import numpy as np

__all__ = ["RawMesh"]


@dataclass(frozen=True)
class RawMesh:
    """Nodes and cell blocks as written in a file.

    - points: (n, 3) float64 coordinates in file order.
    - node_ids: (n,) int64, the id of each node in the file's own numbering.
    - numbering: what the ids are, in words (e.g. "gmsh node tags").
    - blocks: [(cell type, (k, nodes) int64 node *ids*)], in file order; cell types use
      meshio's names ("tetra", "triangle", "tetra10", ...).
    """

    points: np.ndarray
    node_ids: np.ndarray
    numbering: str
    blocks: List[Tuple[str, np.ndarray]]
