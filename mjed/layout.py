"""Names of the memory layouts of per-cell arrays, and the conversion to the engine's layout.

Per-cell element vectors and edge blocks are stored either cell-major (the cell axis first,
what a user indexes: ``gradient[cell, node, component]``) or component-major (the cell axis
last and contiguous, what the engine computes in: every NumPy operation then streams long
rows instead of broadcasting over tiny 3x3 trailing axes). Each layout is named by the
order of its axes, which is what :class:`mjed.sparse.CSRPattern` reads:

    m cell, a node, k component          (element vectors)
    m cell, e edge, r row, c column      (edge blocks d2W/dx_a dx_b, edges in EDGES order)
"""

from __future__ import annotations

from enum import Enum

import numpy as np

__all__ = ["VectorLayout", "BlockLayout", "to_component_major"]


class VectorLayout(str, Enum):
    """Axis order of per-cell node vectors (e.g. the gradient dW/dx_a of each cell)."""

    CELL_MAJOR = "mak"  #: (m, 4, 3)
    COMPONENT_MAJOR = "kam"  #: (3, 4, m), the engine's


class BlockLayout(str, Enum):
    """Axis order of per-cell edge blocks (the six 3x3 blocks K_ab, a < b, of each cell)."""

    CELL_MAJOR = "merc"  #: (m, 6, 3, 3)
    COMPONENT_MAJOR = "rcem"  #: (3, 3, 6, m), the engine's


def to_component_major(A: np.ndarray, out: "np.ndarray | None" = None) -> np.ndarray:
    """(m, ...) -> (..., m), contiguous (written into ``out`` if given)."""
    if out is None:
        return np.ascontiguousarray(np.moveaxis(A, 0, -1))
    np.copyto(out, np.moveaxis(A, 0, -1))
    return out
