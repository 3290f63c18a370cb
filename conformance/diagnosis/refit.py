"""A few numbers of the energy refitted to the engine through the oracle.

Some mistakes change a number that enters the energy non-linearly: a parameter inside an
exponential (Costa's b_ij, Veronda-Westmann's c2), an exponent of J written as a rounded decimal
or as another fraction. No linear fit over the oracle's terms sees them; the oracle evaluated with
that number changed does. :func:`refit` finds the values by Gauss-Newton on the engine's force and
stiffness, each step's derivative by a difference of two oracle evaluations (a parameter or a
constant enters the oracle's form as a dolfinx Constant, so each evaluation reuses the compiled
form), and says whether the engine agrees with the oracle at those values within the case's
tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp

__all__ = ["Refit", "Target", "refit"]

Evaluate = Callable[[Sequence[float]], Tuple[np.ndarray, sp.spmatrix]]


@dataclass(frozen=True)
class Target:
    """What a refit aims at: the engine's force f (n, 3) and stiffness K, the case's error
    scales and its tolerances.
    """

    f: np.ndarray
    K: sp.spmatrix
    s_force: float
    s_stiffness: float
    tol_force: float
    tol_stiffness: float


@dataclass(frozen=True)
class Refit:
    """values: the fitted numbers; force, stiffness: the engine's relative errors against the
    oracle at those values; agrees: both within the tolerances; prediction: the oracle's (f, K)
    there; steps: Gauss-Newton steps taken.
    """

    values: Tuple[float, ...]
    force: float
    stiffness: float
    agrees: bool
    prediction: Tuple[np.ndarray, sp.csr_matrix]
    steps: int
    #: the smallest singular value of the last step's Jacobian with each column scaled by its
    #: value's size: the least change of the relative errors per unit relative change of any
    #: combination of the numbers (near 0: some combination does not change the oracle's answer
    #: on this case, not identified); NaN where no step was taken
    sensitivity: float = float("nan")

    @property
    def residual(self) -> float:
        return max(self.force, self.stiffness)


class _Residual:
    """The engine's (f, K) against the oracle's, as one scaled vector on a fixed pattern."""

    def __init__(self, f, K, s_force: float, s_stiffness: float, K0):
        self.f = np.asarray(f, dtype=np.float64)
        self.K = sp.csr_matrix(K)
        self.sf, self.sK = s_force, s_stiffness
        self.r, self.c = sp.csr_matrix(abs(self.K) + abs(sp.csr_matrix(K0))).nonzero()
        self.Kv = np.asarray(self.K[self.r, self.c]).ravel()

    def vector(self, fo, Ko) -> np.ndarray:
        Ko = sp.csr_matrix(Ko)
        kv = np.asarray(Ko[self.r, self.c]).ravel()
        return np.concatenate([np.ravel(fo - self.f) / self.sf, (kv - self.Kv) / self.sK])

    def errors(self, fo, Ko) -> Tuple[float, float]:
        D = sp.csr_matrix(sp.csr_matrix(Ko) - self.K)
        ef = float(np.linalg.norm(np.asarray(fo) - self.f)) / self.sf
        eK = float(np.sqrt(D.multiply(D).sum())) / self.sK
        return ef, eK


def refit(
    evaluate: Evaluate,
    start: Sequence[float],
    target: Target,
    steps: int = 8,
    give_up: float = 0.5,
) -> Optional[Refit]:
    """The numbers near ``start`` with which the oracle (``evaluate(values) -> (f, K)``) best
    matches the engine's ``target.f``, ``target.K`` (Gauss-Newton, at most ``steps`` steps; a
    value the oracle cannot evaluate raises ValueError there and ends the fit). The fit is
    abandoned (None) when the first step's linear model cannot remove at least ``give_up`` of
    the error: the numbers do not explain it, and the oracle is not asked again.
    """
    x = np.asarray(start, dtype=np.float64)
    try:
        fo, Ko = evaluate(tuple(x))
    except ValueError:
        return None
    res = _Residual(target.f, target.K, target.s_force, target.s_stiffness, Ko)
    ef, eK = res.errors(fo, Ko)
    if ef <= target.tol_force and eK <= target.tol_stiffness:
        # the start itself agrees: no step could remove half of an error at round-off, and
        # the give-up rule below would reject the very values that explain the engine
        return Refit(
            tuple(float(v) for v in x), ef, eK, True, (np.asarray(fo), sp.csr_matrix(Ko)), 0
        )
    r = res.vector(fo, Ko)
    best = (float(np.linalg.norm(r)), x.copy(), (fo, Ko))
    sensitivity = float("nan")
    for step in range(steps):
        h = 1e-6 * np.maximum(np.abs(x), 1e-3)
        cols = []
        try:
            for k in range(x.size):
                y = x.copy()
                y[k] += h[k]
                cols.append((res.vector(*evaluate(tuple(y))) - r) / h[k])
        except ValueError:
            break
        A = np.column_stack(cols)
        sensitivity = float(np.linalg.svd(A * np.maximum(np.abs(x), 1e-3), compute_uv=False)[-1])
        dx, *_ = np.linalg.lstsq(A, -r, rcond=None)
        if step == 0 and np.linalg.norm(r + A @ dx) > give_up * np.linalg.norm(r):
            return None
        # a damped step: halve it until the residual decreases (the energy is not linear in x)
        for _ in range(6):
            y = x + dx
            try:
                fy, Ky = evaluate(tuple(y))
            except ValueError:
                dx = dx / 2
                continue
            ry = res.vector(fy, Ky)
            if np.linalg.norm(ry) < np.linalg.norm(r):
                break
            dx = dx / 2
        else:
            break
        x, r = y, ry
        if np.linalg.norm(r) < best[0]:
            best = (float(np.linalg.norm(r)), x.copy(), (fy, Ky))
        if np.all(np.abs(dx) <= 1e-13 * np.maximum(np.abs(x), 1e-300)):
            break
    _, x, (fo, Ko) = best
    ef, eK = res.errors(fo, Ko)
    return Refit(
        tuple(float(v) for v in x),
        ef,
        eK,
        bool(ef <= target.tol_force and eK <= target.tol_stiffness),
        (np.asarray(fo), sp.csr_matrix(Ko)),
        step + 1 if steps else 0,
        sensitivity,
    )
