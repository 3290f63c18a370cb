"""Errors raised by mjed. All derive from ValueError so that callers who only care about
"bad input" can catch one thing, except IntegrationError: a time step that fails during a run
is not bad input, so it is a RuntimeError.
"""

from __future__ import annotations

__all__ = ["MeshError", "InvertedElementError", "MeshWarning", "IntegrationError"]


class MeshError(ValueError):
    """The mesh is unusable: wrong shapes, bad indices, non-finite or degenerate cells."""


class MeshWarning(UserWarning):
    """The mesh is usable but something about it deserves attention (unused nodes, fixed
    orientation).
    """


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
            f"{len(cells)} inverted or flattened cell(s){where}: {shown}{more}. Pass "
            "allow_inverted=True to evaluate anyway (energies with ln J are then NaN)."
        )


class IntegrationError(RuntimeError):
    """A time step failed; the integrator kept the last accepted state.

    Attributes:
        step: number of the step that failed (1 for the first step of the run).
        time: the time the failed step was heading for.
        reason: "cg_negative_curvature", "cg_max_iterations", "cg_non_finite", "non_finite",
            "inverted", "newton_diverged" or "newton_max_iterations".
        cells: for "inverted", the indices of the inverted cells (else None).
    """

    def __init__(self, step: int, time: float, reason: str, detail: str, *, cells=None):
        self.step = int(step)
        self.time = float(time)
        self.reason = reason
        self.cells = cells
        super().__init__(
            f"time step {self.step} (t = {self.time:.6g} s) failed: {detail}; the integrator kept "
            "the state of the last accepted step"
        )
