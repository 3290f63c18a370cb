"""Veronda-Westmann: W = c1 (exp(c2 (I1b - 3)) - 1) - c1 c2/2 (I2b - 3) + k0/2 (ln J)^2."""

from __future__ import annotations

import math
from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import ISOCHORIC_I1, ISOCHORIC_I2, Material, log_squared, require_positive
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, LinearI2, LogPolynomial, Term, TermGroup, Unity

__all__ = ["VerondaWestmann"]


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
                (Term(ISOCHORIC_I1, I1Power(c2)),),
                exponential=True,
                coefficient=c1 * math.exp(-3.0 * c2),
            ),
            TermGroup(
                (
                    Term(ISOCHORIC_I2, LinearI2(-0.5 * c1 * c2)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, 1.5 * c1 * c2 - c1), Unity()),
                )
            ),
        )


def energy(p, k):
    c1, c2 = p("c1"), p("c2")
    return (
        c1 * (k.exp(c2 * (k.I1b - 3.0)) - 1.0)
        - 0.5 * c1 * c2 * (k.I2b - 3.0)
        + 0.5 * p("k0") * k.lnJ**2
    )


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b, I2b (for the classical element)."""
    c1, c2 = p.c1, p.c2
    e = m.exp(c2 * (I1b - 3.0))
    return (
        c1 * (e - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0),
        c1 * c2 * e,
        -0.5 * c1 * c2,
        c1 * c2 * c2 * e,
        0,
        0,
    )


declare(
    Declaration(
        material=VerondaWestmann,
        formula="c1 (exp(c2 (I1b - 3)) - 1) - c1 c2 / 2 (I2b - 3) + k0/2 (ln J)^2",
        parameters="`c1` (Pa), `c2` (dimensionless), `k0` (Pa)",
        default=VerondaWestmann(c1=1500.0, c2=1.4, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("c1", m.c1), ("c2", m.c2)), m.k0
        ),
        aliases=("vw", "verondawestman"),
        sofa=("VerondaWestman", ("c1", "c2", "k0")),
        order=40,
        ranges={"c1": (0.05, 20.0), "c2": (0.05, 2.0), "k0": (0.05, 20.0)},
        examples={"VerondaWestmann": VerondaWestmann(c1=0.8, c2=1.2, k0=5.0)},
    )
)
