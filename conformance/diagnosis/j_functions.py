"""Is a per-cell quantity one function of J? The test that keeps a reading from claiming "the
volumetric energy" or "the J curvature" for a change that depends on more than J (an isochoric
invariant, a cell's own pressure).

The cells' values are compared in the order of their J. Both tests need a state where J varies
(eight distinct values or more; four for the energy test); on a state with one J (a homogeneous
stretch) nothing can be told and the readings say so.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "J_ONLY",
    "J_FUNCTION_STEPS",
    "j_function_line",
    "j_function_residual",
    "j_function_steps",
]


#: A per-cell fit is read as one function U(J) only when its dU/dJ values, cell to cell in the
#: order of J, change as the trapezoid rule on its d2U/dJ2 says, within this relative residual
#: (the rule's own error, h^2/12 of the third derivative over the steps h in J, is far below).
J_ONLY = 1e-2


def j_function_residual(J: np.ndarray, dU1: np.ndarray, dU2: np.ndarray) -> float:
    """Relative residual of per-cell values dU1 = g(J_c) and derivatives dU2 = g'(J_c) (all
    (m,)) as one function g of J: the cells sorted by J, each step of dU1 against the trapezoid
    rule on dU2. Small when the per-cell volumetric change is a J-only energy's, O(1) when it
    depends on the cell otherwise (e.g. on an isochoric invariant). NaN with fewer than 4
    distinct J (then nothing can be told).
    """
    if np.unique(np.round(J, 12)).size < 4:
        return float("nan")
    o = np.argsort(J, kind="stable")
    j, g, dg = J[o], dU1[o], dU2[o]
    step = np.diff(g)
    trap = 0.5 * (dg[1:] + dg[:-1]) * np.diff(j)
    scale = float(np.linalg.norm(step) + np.linalg.norm(trap))
    if scale == 0.0:
        return 0.0
    return float(np.linalg.norm(step - trap)) / scale


#: A per-cell tangent coefficient is read as one function of J when, the cells sorted by J, each
#: value is predicted by its two neighbours in J (linear interpolation) to within a fraction of
#: the values' spread (medians of both): about 1e-4 for a smooth function of J on the kits'
#: meshes (7e-6 for a volumetric f'' slipped), 0.2 to 1 for values that depend on the cell
#: otherwise (an isochoric invariant), and 0.026 for a term's f''(J) times its g(C) near rest
#: (Gent's J^(-2/3) I1 term: a function of J times an I1 that barely varies). The line is
#: :func:`j_function_line`: at least this, or ten times what a smooth function of J with the
#: same trend leaves on the same cells (coarse meshes and steep functions interpolate worse).
J_FUNCTION_STEPS = 1e-3


def j_function_line(J: np.ndarray, values: np.ndarray) -> float:
    """The most :func:`j_function_steps` may be for ``values`` (m,) to be one function of J (m,):
    J_FUNCTION_STEPS, or ten times the steps of their cubic trend in J (a smooth function with
    their shape, interpolated between the same cells), whichever is larger.
    """
    Jc = np.asarray(J, dtype=float) - float(np.mean(J))
    scale = float(np.max(np.abs(Jc))) or 1.0
    trend = np.polyval(np.polyfit(Jc / scale, np.asarray(values, dtype=float), 3), Jc / scale)
    smooth = j_function_steps(J, trend)
    return max(J_FUNCTION_STEPS, 10.0 * smooth) if np.isfinite(smooth) else J_FUNCTION_STEPS


def j_function_steps(J: np.ndarray, values: np.ndarray) -> float:
    """How far ``values`` (m,) are from one function of J (m,): the cells sorted by J, the median
    of |v_i - (v_(i-1), v_(i+1)) interpolated at J_i| over the median absolute deviation of v.
    Small for one function of J (its interpolation error), O(1) when the values depend on the
    cell otherwise. Medians, so that the few wide gaps at the ends of a wide range of J do not
    count. NaN with fewer than 8 distinct J (nothing can be told), 0 for constant values.
    """
    if np.unique(np.round(J, 12)).size < 8:
        return float("nan")
    o = np.argsort(J, kind="stable")
    j, v = np.asarray(J, dtype=float)[o], np.asarray(values, dtype=float)[o]
    gap = j[2:] - j[:-2]
    keep = gap > 0
    w = (j[1:-1] - j[:-2])[keep] / gap[keep]
    between = v[:-2][keep] + w * (v[2:] - v[:-2])[keep]
    spread = float(np.median(np.abs(v - np.median(v))))
    if spread == 0.0:
        return 0.0
    return float(np.median(np.abs(v[1:-1][keep] - between))) / spread
