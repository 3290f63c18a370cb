"""The forms of law the classical element knows; a material declares which one is its own.

These are data only: the classical element (reference_fem.classical_materials, its compiled
kernel reference_fem.classical_codegen) builds S = 2 dW/dC and the elasticity tensor of each
form by the textbook route (Holzapfel, Bonet & Wood), independently of the MJED terms. A new
material whose law fits a form needs nothing in reference_fem: e.g. any W = Psi(I1b, I2b) +
k0/2 (ln J)^2 is a :class:`Decoupled` with the derivatives of its Psi written out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Optional, Tuple

import numpy as np

__all__ = [
    "FORMS",
    "GreenLagrangeQuadratic",
    "CompressibleNeoHookean",
    "IsochoricPsi",
    "Decoupled",
    "SpectralOgden",
    "FibreExponential",
]


@dataclass(frozen=True)
class GreenLagrangeQuadratic:
    """W = lam/2 (tr E)^2 + mu tr(E^2)."""

    mu: float
    lam: float


@dataclass(frozen=True)
class CompressibleNeoHookean:
    """W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2."""

    mu: float
    lam: float


#: ``psi(p, I1b, I2b, m) -> (Psi, Psi_1, Psi_2, Psi_11, Psi_12, Psi_22)``: the isochoric energy
#: and its derivatives by I1b and I2b. ``p.name`` reads a parameter, ``m.exp`` and ``m.log``
#: are the functions (NumPy's, or the compiled kernel's source writer); a derivative that is
#: identically zero is the number 0 (the kernel then drops its terms).
PsiFunction = Callable[[Any, Any, Any, Any], Tuple[Any, Any, Any, Any, Any, Any]]


@dataclass(frozen=True, eq=False)
class IsochoricPsi:
    """A named :data:`PsiFunction`; equal and hashed by the function, shown by its name (a
    compiled kernel's shape holds it, and its printed form must not change between runs).
    """

    function: PsiFunction

    def __eq__(self, other: object) -> bool:
        return isinstance(other, IsochoricPsi) and other.function is self.function

    def __hash__(self) -> int:
        return hash(self.function)

    def __repr__(self) -> str:
        return f"IsochoricPsi({self.function.__module__}.{self.function.__qualname__})"


@dataclass(frozen=True)
class Decoupled:
    """W = Psi(I1b, I2b) + k0/2 (ln J)^2; ``parameters`` the (name, value) pairs Psi reads."""

    psi: IsochoricPsi
    parameters: Tuple[Tuple[str, float], ...]
    k0: float


@dataclass(frozen=True)
class SpectralOgden:
    """W = mu/alpha^2 (J^(-alpha/3) sum_i lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2."""

    mu: float
    alpha: float
    k0: float


@dataclass(frozen=True, eq=False)
class FibreExponential:
    """W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum_ij B_ij (R^T E R)_ij^2;
    frame R None (identity), (3, 3) or (m, 3, 3).
    """

    a: float
    k0: float
    B: np.ndarray
    frame: Optional[np.ndarray] = None


#: Every form the classical element knows (a declaration's ``classical`` must return one).
FORMS = (GreenLagrangeQuadratic, CompressibleNeoHookean, Decoupled, SpectralOgden, FibreExponential)
