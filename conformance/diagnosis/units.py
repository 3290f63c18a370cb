"""Lengths in other units: an engine that reads the mesh in another length unit (mm taken as m,
or converted twice) while the moduli stay in Pa.

With every length multiplied by s (rest and current positions alike), F is unchanged, so is the
stress P; the rest volume V0 scales by s^3 and the shape gradients D by 1/s. The P1 element
force f_a = -V0 P D_a therefore scales by s^2, the element matrix K_ab = V0 D_a . A . D_b by s,
and the energy V0 W by s^3. Force and stiffness scaled by different factors that are s^2 and s
of one s are that mistake; each alone, or both by one factor, is another
(:func:`conformance.diagnosis.hypotheses.scale_corrections`).

The other way round, an engine that differentiates with respect to positions in another unit
(a step or a hyper-dual or complex seed of 1e-3, "one millimetre", not divided out; positions
converted to mm only inside the derivative) computes the right energy but dE/d(x/t) = t dE/dx
and t^2 d2E/dx2: force scaled by t and stiffness by t^2 (:func:`fit_derivative_scale`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.hypotheses import fit_scale

__all__ = [
    "LengthScale",
    "DerivativeScale",
    "fit_length_scale",
    "fit_derivative_scale",
    "FORCE_POWER",
    "STIFFNESS_POWER",
    "ENERGY_POWER",
]

#: Powers of the length factor s in the force, the stiffness and the energy of a P1 element.
FORCE_POWER, STIFFNESS_POWER, ENERGY_POWER = 2, 1, 3

#: Force and stiffness ratios agree with one s when s^2 and the force ratio differ by less.
_AGREE = 1e-6

#: Usual unit mix-ups, s (the engine's length / the kit's) -> words.
_NAMED = {
    1e-3: "e.g. coordinates already in m divided by 1000 (taken as mm)",
    1e3: "e.g. coordinates in mm read as m, or m multiplied by 1000",
    1e-2: "e.g. coordinates already in m divided by 100 (taken as cm)",
    1e2: "e.g. coordinates in cm read as m",
    0.0254: "e.g. coordinates taken as inches",
    1 / 0.0254: "e.g. inches read as m",
}


@dataclass(frozen=True)
class LengthScale:
    """s: the engine's lengths / the kit's; force, stiffness: the output divided by s^2 and s."""

    s: float
    force_ratio: float
    stiffness_ratio: float
    force: np.ndarray
    stiffness: sp.csr_matrix

    def words(self) -> str:
        named = [w for v, w in _NAMED.items() if abs(self.s / v - 1.0) < 1e-6]
        return (
            f"lengths in other units: your engine's lengths are {self.s:.6g} times the kit's "
            f"({named[0] if named else 'a length unit mixed up'}; moduli in Pa): force scaled "
            f"by s^2 = {self.force_ratio:.6g}, stiffness by s = {self.stiffness_ratio:.6g}"
        )


def _sparse_ratio(K_e: sp.spmatrix, K_o: sp.spmatrix) -> Optional[float]:
    """Engine / oracle factor fitted on the stiffness (None when the oracle's is zero)."""
    oo = float(sp.csr_matrix(K_o).multiply(K_o).sum())
    return None if oo == 0 else float(sp.csr_matrix(K_e).multiply(K_o).sum()) / oo


def _log_ratios(f_o, K_o, f_e, K_e) -> Optional[Tuple[float, float, float, float]]:
    """(r, k, ln r, ln k): the engine / oracle factors fitted on the force and on the stiffness
    and their logarithms, or None when either is missing, not positive or not finite. In
    logarithms, so that ratios near 1e300 (garbage output) never overflow a power.
    """
    k = _sparse_ratio(K_e, K_o)
    r = fit_scale(np.asarray(f_o), np.asarray(f_e))  # engine / oracle on the force
    if k is None or r is None or k <= 0 or r <= 0:
        return None
    lr, lk = np.log(r), np.log(k)
    if not (np.isfinite(lr) and np.isfinite(lk)):
        return None
    return r, k, lr, lk


def fit_length_scale(
    f_o: np.ndarray, K_o: sp.spmatrix, f_e: np.ndarray, K_e: sp.spmatrix
) -> Optional[LengthScale]:
    """The length factor s whose force (x s^2) and stiffness (x s) scalings are the engine's, or
    None: the force or the stiffness is zero (one scaling alone names no s), s <= 0, the two
    ratios disagree, or they are the same factor (a plain global scale, not a unit).

    f_o, f_e: (n, 3); K_o, K_e: (3n, 3n).
    """
    ratios = _log_ratios(f_o, K_o, f_e, K_e)
    if ratios is None:
        return None
    r, k, lr, lk = ratios
    if abs(lr - FORCE_POWER * lk) > _AGREE or abs(lr - lk) <= _AGREE:
        return None
    s = k  # the stiffness scales by s itself
    return LengthScale(
        s,
        r,
        k,
        np.asarray(f_e) / s**FORCE_POWER,
        (sp.csr_matrix(K_e) / s**STIFFNESS_POWER).tocsr(),
    )


@dataclass(frozen=True)
class DerivativeScale:
    """t: the factor of each derivative (the force scaled by t, the stiffness by t^2); force,
    stiffness: the output divided by t and t^2.
    """

    t: float
    force: np.ndarray
    stiffness: sp.csr_matrix

    def words(self) -> str:
        return (
            f"derivatives taken with respect to positions in another unit: force scaled by "
            f"t = {self.t:.6g} and stiffness by t^2 = {self.t**2:.6g} (each derivative per "
            f"{1.0 / self.t:.6g} of the kit's length: e.g. a finite-difference step, or a "
            "complex or hyper-dual seed, of that size not divided out, or positions converted "
            "to another length unit only where they are differentiated)"
        )


def fit_derivative_scale(
    f_o: np.ndarray, K_o: sp.spmatrix, f_e: np.ndarray, K_e: sp.spmatrix
) -> Optional[DerivativeScale]:
    """The factor t whose force (x t) and stiffness (x t^2) scalings are the engine's, or None:
    the force or the stiffness is zero, t <= 0, the two ratios disagree, or they are the same
    factor (a plain global scale).

    f_o, f_e: (n, 3); K_o, K_e: (3n, 3n).
    """
    ratios = _log_ratios(f_o, K_o, f_e, K_e)
    if ratios is None:
        return None
    r, k, lr, lk = ratios
    if abs(lk - 2.0 * lr) > _AGREE or abs(lr - lk) <= _AGREE:
        return None
    return DerivativeScale(r, np.asarray(f_e) / r, (sp.csr_matrix(K_e) / r**2).tocsr())
