"""Mooney-Rivlin: W = c1 (I1b - 3) + c2 (I2b - 3) + k0/2 (ln J)^2."""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import (
    ISOCHORIC_I1,
    ISOCHORIC_I2,
    Material,
    log_squared,
    require_finite,
    require_positive,
)
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, LinearI2, LogPolynomial, Term, TermGroup, Unity

__all__ = ["MooneyRivlin"]


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
                "MooneyRivlin: parameters c1 + c2 must be > 0 (shear modulus 2 (c1 + c2)), "
                f"got {self.c1 + self.c2!r}"
            )

    def decomposition(self):
        c1, c2 = self.c1, self.c2
        return (
            TermGroup(
                (
                    Term(ISOCHORIC_I1, I1Power(c1)),
                    Term(ISOCHORIC_I2, LinearI2(c2)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, -3.0 * (c1 + c2)), Unity()),
                )
            ),
        )


def energy(p, k):
    return p("c1") * (k.I1b - 3.0) + p("c2") * (k.I2b - 3.0) + 0.5 * p("k0") * k.lnJ**2


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b, I2b (for the classical element)."""
    return p.c1 * (I1b - 3.0) + p.c2 * (I2b - 3.0), p.c1, p.c2, 0, 0, 0


declare(
    Declaration(
        material=MooneyRivlin,
        formula="c1 (I1b - 3) + c2 (I2b - 3) + k0/2 (ln J)^2",
        parameters="`c1`, `c2`, `k0` (Pa)",
        default=MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("c1", m.c1), ("c2", m.c2)), m.k0
        ),
        aliases=("mr",),
        sofa=("MooneyRivlin", ("c1", "c2", "k0")),
        order=30,
        ranges={"c1": (0.05, 20.0), "c2": (0.0, 5.0), "k0": (0.05, 20.0)},
        examples={"MooneyRivlin": MooneyRivlin(c1=0.7, c2=0.4, k0=5.0)},
    )
)
