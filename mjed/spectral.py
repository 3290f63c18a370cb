"""Invariant functions of the eigenvalues of C (Ogden), with the exact spectral tangent.

    g = c sum_n lambda_n^q = c tr(C^q),  S = 2 c q C^(q-1),
    dS/dC : H = 2 c q sum_{n,l} theta_nl P_n H P_l,

where P_n are the eigenprojectors of C and theta the divided differences of t -> t^(q-1):
theta_nl = (lambda_n^(q-1) - lambda_l^(q-1)) / (lambda_n - lambda_l), with the limit
(q-1) lambda^(q-2) when two eigenvalues coincide (always at rest, where C = Id).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Tuple

import numpy as np

from mjed.terms import InvariantFunction, TangentPair

__all__ = ["power_divided_differences", "EigenPowerSum"]


def power_divided_differences(lam: np.ndarray, p: float) -> np.ndarray:
    """theta_nl = (lam_n^p - lam_l^p) / (lam_n - lam_l), limit p lam^(p-1) on ties.

    Written as lam_l^(p-1) expm1(p log1p(x)) / x with x = (lam_n - lam_l)/lam_l, which has no
    cancellation when the eigenvalues are close, and whose x -> 0 limit is exactly p.

    lam: (m, 3) positive. Returns (m, 3, 3), symmetric.
    """
    ln = lam[:, :, None]
    ll = lam[:, None, :]
    x = (ln - ll) / ll
    small = np.abs(x) < 1e-12
    xs = np.where(small, 1.0, x)
    ratio = np.where(small, p * (1.0 + 0.5 * (p - 1.0) * x), np.expm1(p * np.log1p(xs)) / xs)
    theta = ll ** (p - 1.0) * ratio
    return 0.5 * (theta + np.swapaxes(theta, 1, 2))


@dataclass(frozen=True)
class EigenPowerSum(InvariantFunction):
    """g = c sum_n lambda_n(C)^q.

    tangent "exact": the spectral derivative (divided differences). tangent "sofa": SOFA's
    MJED approximation d(C^p) : H ~ p C^((p-1)/2) H C^((p-1)/2), exact only for H coaxial
    with C; kept for teaching, never the default.
    """

    c: float
    q: float
    tangent_mode: str = "exact"
    tangent: Tuple[TangentPair, ...] = field(init=False, default=(TangentPair("spectral"),))

    def __post_init__(self):
        if self.tangent_mode not in ("exact", "sofa"):
            raise ValueError(f"tangent must be 'exact' or 'sofa', got {self.tangent_mode!r}")

    def _power(self, kin) -> np.ndarray:
        """lambda_n^(q-1), (m, 3), once per state (the value and the stress both need it)."""
        return kin.memo(("eigen power", self.q), lambda: kin.eig[0] ** (self.q - 1.0))

    def value(self, kin):
        return self.c * (self._power(kin) * kin.eig[0]).sum(axis=1)

    def stress_t(self, kin):
        # S = 2 c q V diag(lam^(q-1)) V^T, formed component-major: S_ij = sum_n V_in w_n V_jn.
        m = kin.m
        V_t = np.ascontiguousarray(np.moveaxis(kin.eig[1], 0, -1))  # [i, n] = (v_n)_i
        w_t = np.ascontiguousarray((2.0 * self.c * self.q) * self._power(kin).T)  # (3, m)
        return np.einsum("inm,jnm->ijm", V_t * w_t, V_t, out=np.empty((3, 3, m)))

    def tangent_coefficients(self, kin):
        lam = kin.eig[0]
        p = self.q - 1.0
        if self.tangent_mode == "exact":
            theta = power_divided_differences(lam, p)
        else:
            r = lam ** (0.5 * (p - 1.0))
            theta = p * r[:, :, None] * r[:, None, :]
        return (2.0 * self.c * self.q * theta,)
