"""Errors raised by mjed. All derive from ValueError so that callers who only care about
"bad input" can catch one thing."""

from __future__ import annotations

__all__ = ["MeshError", "InvertedElementError", "MeshWarning"]


class MeshError(ValueError):
    """The mesh is unusable: wrong shapes, bad indices, non-finite or degenerate cells."""


class MeshWarning(UserWarning):
    """The mesh is usable but something about it deserves attention (unused nodes, fixed orientation)."""


class InvertedElementError(ValueError):
    """Current positions give J <= 0 in at least one cell.

    Attributes:
        cells: indices of the offending cells (all of them).
        J: their volume ratios.
    """

    def __init__(self, cells, J, *, context: str = ""):
        self.cells = cells
        self.J = J
        shown = ", ".join(f"cell {c} (J={j:.3g})" for c, j in zip(cells[:5], J[:5]))
        more = f" and {len(cells) - 5} more" if len(cells) > 5 else ""
        where = f" {context}" if context else ""
        super().__init__(
            f"{len(cells)} inverted or flattened cell(s){where}: {shown}{more}. "
            "Pass allow_inverted=True to evaluate anyway (energies with ln J are then NaN)."
        )
