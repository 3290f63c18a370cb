"""Taylor remainder tests: derivative checks that need no oracle.

For a smooth map phi with derivative dphi, the remainder ::

    r(eps) = || phi(x + eps v) - phi(x) - eps dphi(x) v ||

falls like eps^2. Halving eps four times and reading log2 of successive ratios gives the
convergence rate; a wrong derivative gives rate 1 (or 0).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["taylor_rates", "energy_force_rates", "force_stiffness_rates"]


def taylor_rates(
    phi: Callable, dphi_v, x: np.ndarray, v: np.ndarray, eps0: float, n: int = 4
) -> np.ndarray:
    """Rates log2(r(eps_i) / r(eps_{i+1})) for eps_i = eps0 / 2^i.

    Args:
        phi: x -> scalar or array.
        dphi_v: the directional derivative dphi(x) v (same shape as phi(x)).
        x, v: point and direction, same shape.
    """
    base = np.asarray(phi(x))
    r = []
    for i in range(n):
        eps = eps0 / 2**i
        r.append(np.linalg.norm(np.asarray(phi(x + eps * v)) - base - eps * np.asarray(dphi_v)))
    r = np.array(r)
    return np.log2(r[:-1] / r[1:])


def energy_force_rates(field, x: np.ndarray, v: np.ndarray, eps0: float) -> np.ndarray:
    """Rates of the energy remainder with the force as derivative (dW.v = -f.v)."""
    return taylor_rates(field.energy, -np.sum(field.force(x) * v), x, v, eps0)


def force_stiffness_rates(field, x: np.ndarray, v: np.ndarray, eps0: float) -> np.ndarray:
    """Rates of the force remainder with the stiffness as derivative (df.v = -K v)."""
    Kv = (field.stiffness(x) @ v.ravel()).reshape(v.shape)
    return taylor_rates(field.force, -Kv, x, v, eps0)
