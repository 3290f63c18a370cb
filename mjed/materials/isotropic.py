"""Isotropic materials as MJED terms (their energies are listed in mjed/materials/__init__.py).

Each decomposition is written so that W = 0 at rest: the constant that makes it so is folded
into the volumetric term's f(J), as in the MJED plugin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mjed.materials.base import Material, require_finite, require_positive
from mjed.terms import (
    GreenLagrangeQuadratic,
    I1Power,
    JPower,
    LinearI2,
    LogPolynomial,
    Term,
    TermGroup,
    Unity,
)

__all__ = [
    "StVenantKirchhoff",
    "NeoHookean",
    "MooneyRivlin",
    "VerondaWestmann",
    "ArrudaBoyce",
    "Ogden",
    "ARRUDA_BOYCE_COEFFICIENTS",
]

# Isochoric invariants: I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2.
_ISO1 = JPower(-2.0 / 3.0)
_ISO2 = JPower(-4.0 / 3.0)


def _check_lame(obj, mu: float, lam: float) -> None:
    require_positive(obj, "mu")
    require_finite(obj, "lam")
    if 3.0 * lam + 2.0 * mu <= 0:
        raise ValueError(
            f"{type(obj).__name__}: parameter lam must give a positive bulk modulus lam + 2 mu/3, "
            f"got lam={lam!r}"
        )


@dataclass(frozen=True)
class StVenantKirchhoff(Material):
    """W = lam/2 (tr E)^2 + mu tr(E^2). One term with f = 1."""

    mu: float
    lam: float

    def __post_init__(self):
        _check_lame(self, self.mu, self.lam)

    def decomposition(self):
        return (TermGroup((Term(JPower(0.0), GreenLagrangeQuadratic(self.mu, self.lam)),)),)


@dataclass(frozen=True)
class NeoHookean(Material):
    """W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 (compressible, not isochoric)."""

    mu: float
    lam: float

    def __post_init__(self):
        _check_lame(self, self.mu, self.lam)

    def decomposition(self):
        mu, lam = self.mu, self.lam
        return (
            TermGroup(
                (
                    Term(JPower(0.0), I1Power(0.5 * mu)),
                    Term(LogPolynomial(0.5 * lam, -mu, -1.5 * mu), Unity()),
                )
            ),
        )


@dataclass(frozen=True)
class MooneyRivlin(Material):
    """W = c1 (I1b - 3) + c2 (I2b - 3) + k0/2 (ln J)^2."""

    c1: float
    c2: float
    k0: float

    def __post_init__(self):
        require_finite(self, "c1", "c2")
        require_positive(self, "k0")
        if self.c1 + self.c2 <= 0:
            raise ValueError(
                "MooneyRivlin: parameters c1 + c2 must be > 0 (shear modulus 2 (c1 + c2)), got "
                f"{self.c1 + self.c2!r}"
            )

    def decomposition(self):
        c1, c2 = self.c1, self.c2
        return (
            TermGroup(
                (
                    Term(_ISO1, I1Power(c1)),
                    Term(_ISO2, LinearI2(c2)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, -3.0 * (c1 + c2)), Unity()),
                )
            ),
        )


@dataclass(frozen=True)
class VerondaWestmann(Material):
    """W = c1 (exp(c2 (I1b - 3)) - 1) - c1 c2/2 (I2b - 3) + k0/2 (ln J)^2.

    The exponential is one exponential group, c1 e^(-3 c2) exp(c2 J^(-2/3) I1).
    """

    c1: float
    c2: float
    k0: float

    def __post_init__(self):
        require_positive(self, "c1", "c2", "k0")

    def decomposition(self):
        c1, c2 = self.c1, self.c2
        return (
            TermGroup(
                (Term(_ISO1, I1Power(c2)),), exponential=True, coefficient=c1 * math.exp(-3.0 * c2)
            ),
            TermGroup(
                (
                    Term(_ISO2, LinearI2(-0.5 * c1 * c2)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, 1.5 * c1 * c2 - c1), Unity()),
                )
            ),
        )


#: Coefficients c_1..c_5 of the five-term inverse-Langevin (8-chain) series of the
#: Arruda-Boyce energy: part of the material's definition, shared by every formula of it.
ARRUDA_BOYCE_COEFFICIENTS = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


@dataclass(frozen=True)
class ArrudaBoyce(Material):
    """W = mu sum_{i=1..5} c_i N^(1-i) (I1b^i - 3^i) + k0/2 (ln J)^2 (SOFA fixes N = 8)."""

    mu: float
    k0: float
    N: float = 8.0

    def __post_init__(self):
        require_positive(self, "mu", "k0", "N")

    def decomposition(self):
        mu, N = self.mu, self.N
        coeffs = [mu * c * N ** (1 - i) for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)]
        deviatoric = tuple(
            Term(JPower(-2.0 * i / 3.0), I1Power(a, i)) for i, a in enumerate(coeffs, start=1)
        )
        rest = sum(a * 3.0**i for i, a in enumerate(coeffs, start=1))
        volumetric = Term(LogPolynomial(0.5 * self.k0, 0.0, -rest), Unity())
        return (TermGroup(deviatoric + (volumetric,)),)


@dataclass(frozen=True)
class Ogden(Material):
    """Order-1 Ogden: W = mu/alpha^2 (J^(-alpha/3) sum_i lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2.

    lambda_i are the eigenvalues of C. tangent="exact" (default) differentiates the
    eigenvalues exactly; tangent="sofa" is SOFA's MJED coaxial approximation, which is not the
    Hessian of W (for teaching and comparison only).
    """

    mu: float
    alpha: float
    k0: float
    tangent: str = "exact"

    def __post_init__(self):
        require_positive(self, "mu", "k0")
        require_finite(self, "alpha")
        if self.alpha == 0:
            raise ValueError("Ogden: parameter alpha must be non-zero")
        if self.tangent not in ("exact", "sofa"):
            raise ValueError(
                f"Ogden: parameter tangent must be 'exact' or 'sofa', got {self.tangent!r}"
            )

    def decomposition(self):
        from mjed.spectral import EigenPowerSum

        mu, alpha = self.mu, self.alpha
        c = mu / alpha**2
        return (
            TermGroup(
                (
                    Term(JPower(-alpha / 3.0), EigenPowerSum(c, 0.5 * alpha, self.tangent)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, -3.0 * c), Unity()),
                )
            ),
        )
