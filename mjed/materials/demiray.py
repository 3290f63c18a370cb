"""Demiray: W = a/(2b) (exp(b (I1b - 3)) - 1) + k0/2 (ln J)^2.

The exponential law of soft biological tissue (H. Demiray, "A note on the elasticity of soft
biological tissues", J. Biomech. 5, 1972), used for arterial walls, the myocardium's and the
liver's matrix and the brain; the isotropic ground matrix of Holzapfel-Gasser-Ogden arteries
is often taken as this law. ``a`` is the shear modulus at small strain, ``b`` the stiffening.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import ISOCHORIC_I1, Material, log_squared, require_positive
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, LogPolynomial, Term, TermGroup, Unity

__all__ = ["Demiray"]


@dataclass(frozen=True)
class Demiray(Material):
    """W = a/(2b) (exp(b (I1b - 3)) - 1) + k0/2 (ln J)^2.

    The exponential is one exponential group, a/(2b) e^(-3b) exp(b J^(-2/3) I1); the constant
    -a/(2b) that makes W = 0 at rest sits in the volumetric term.
    """

    a: float
    b: float
    k0: float

    def __post_init__(self):
        require_positive(self, "a", "b", "k0")

    def decomposition(self):
        a, b = self.a, self.b
        return (
            TermGroup(
                (Term(ISOCHORIC_I1, I1Power(b)),),
                exponential=True,
                coefficient=a / (2.0 * b) * math.exp(-3.0 * b),
            ),
            TermGroup((Term(LogPolynomial(0.5 * self.k0, 0.0, -a / (2.0 * b)), Unity()),)),
        )


def energy(p, k):
    a, b = p("a"), p("b")
    return a / (2.0 * b) * (k.exp(b * (k.I1b - 3.0)) - 1.0) + 0.5 * p("k0") * k.lnJ**2


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b, I2b (for the classical element)."""
    a, b = p.a, p.b
    e = m.exp(b * (I1b - 3.0))
    return (a / (2.0 * b) * (e - 1.0), 0.5 * a * e, 0, 0.5 * a * b * e, 0, 0)


declare(
    Declaration(
        material=Demiray,
        formula="a/(2 b) (exp(b (I1b - 3)) - 1) + k0/2 (ln J)^2",
        notes="Demiray (1972), soft biological tissue",
        parameters="`a`, `k0` (Pa), `b` (dimensionless)",
        default=Demiray(a=3000.0, b=1.2, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("a", m.a), ("b", m.b)), m.k0
        ),
        order=100,
        ranges={"a": (0.05, 20.0), "b": (0.05, 2.0), "k0": (0.05, 20.0)},
        examples={"Demiray": Demiray(a=1.1, b=1.3, k0=5.0)},
    )
)
