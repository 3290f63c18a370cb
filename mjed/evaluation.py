"""What one evaluation of the engine asks for and returns, per cell."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Optional

import numpy as np

__all__ = ["Want", "Evaluation", "CellEvaluation"]


class Want(enum.Flag):
    """The per-cell quantities an evaluation computes (combine with ``|``).

    ENERGY: V0 W. GRADIENT: V0 dW/dx_a (the force is its negated assembly). STIFFNESS: the
    edge blocks V0 d2W/dx_a dx_b. STRESS: S = 2 dW/dC (not multiplied by V0) and F, what a
    stress-based model (the viscous history) needs. J is always returned: it is formed first
    and checked for inverted cells.
    """

    ENERGY = enum.auto()
    GRADIENT = enum.auto()
    STIFFNESS = enum.auto()
    STRESS = enum.auto()


@dataclass(frozen=True)
class CellEvaluation:
    """The engine's native result: per-cell quantities in component-major layout.

    energy: (m,) V0 W, or None if not asked. gradient: (3, 4, m), [k, a] = V0 dW/dx_a,k, or
    None. blocks: (3, 3, 6, m), [r, c, e] = V0 (d2W/dx_a dx_b)_rc for edge e = (a, b) of
    mjed.sparse.EDGES, or None. J: (m,). F: (m, 3, 3), with the stress. pk2: (m, 3, 3) second
    Piola-Kirchhoff stress 2 dW/dC per unit rest volume, or None. (See mjed.layout for the
    layout names.)
    """

    energy: Optional[np.ndarray]
    gradient: Optional[np.ndarray]
    blocks: Optional[np.ndarray]
    J: np.ndarray
    F: Optional[np.ndarray] = None
    pk2: Optional[np.ndarray] = None

    def public(self) -> "Evaluation":
        """The cell-major views of the same arrays (no copy)."""
        gradient = None if self.gradient is None else self.gradient.transpose(2, 1, 0)
        blocks = None if self.blocks is None else self.blocks.transpose(3, 2, 0, 1)
        return Evaluation(self.energy, gradient, blocks, self.J, self.F, self.pk2)


@dataclass(frozen=True)
class Evaluation:
    """Per-cell results at one state, cell-major, all multiplied by the rest volume but pk2.

    energy: (m,); gradient: (m, 4, 3) dW/dx_a; edge_blocks: (m, 6, 3, 3) d2W/dx_a dx_b for
    the edges of EDGES; J: (m,); F: (m, 3, 3); pk2: (m, 3, 3) second Piola-Kirchhoff stress
    2 dW/dC per unit rest volume. Quantities not asked for are None.
    """

    energy: Optional[np.ndarray]
    gradient: Optional[np.ndarray]
    edge_blocks: Optional[np.ndarray]
    J: np.ndarray
    F: Optional[np.ndarray] = None
    pk2: Optional[np.ndarray] = None
