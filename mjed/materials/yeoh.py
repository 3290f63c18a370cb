"""Yeoh: W = c10 (I1b - 3) + c20 (I1b - 3)^2 + c30 (I1b - 3)^3 + k0/2 (ln J)^2."""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import (
    ISOCHORIC_I1,
    Material,
    log_squared,
    require_finite,
    require_positive,
)
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, LogPolynomial, Power, Term, TermGroup, Unity

__all__ = ["Yeoh"]


@dataclass(frozen=True)
class Yeoh(Material):
    """W = c10 (I1b - 3) + c20 (I1b - 3)^2 + c30 (I1b - 3)^3 + k0/2 (ln J)^2.

    The squared and cubed terms are each a power of a separable sum, (I1b - 3)^n with
    u = J^(-2/3) I1 and shift -3: no expansion in powers of I1b, so nothing cancels near
    rest. Valid parameters: c10 > 0 (the initial shear modulus is 2 c10), c20 and c30
    finite, k0 > 0.
    """

    c10: float
    c20: float
    c30: float
    k0: float

    def __post_init__(self):
        require_positive(self, "c10", "k0")
        require_finite(self, "c20", "c30")

    def decomposition(self):
        u = (Term(ISOCHORIC_I1, I1Power(1.0)),)
        groups = [
            TermGroup(
                (
                    Term(ISOCHORIC_I1, I1Power(self.c10)),
                    Term(LogPolynomial(0.5 * self.k0, 0.0, -3.0 * self.c10), Unity()),
                )
            )
        ]
        for n, c in ((2, self.c20), (3, self.c30)):
            if c != 0.0:  # a zero term would only cost a rank-one update
                groups.append(TermGroup(u, coefficient=c, function=Power(float(n), -3.0)))
        return tuple(groups)


def energy(p, k):
    x = k.I1b - 3.0
    return p("c10") * x + p("c20") * x**2 + p("c30") * x**3 + 0.5 * p("k0") * k.lnJ**2


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b (for the classical element)."""
    x = I1b - 3.0
    W = (p.c10 + (p.c20 + p.c30 * x) * x) * x
    return W, p.c10 + (2.0 * p.c20 + 3.0 * p.c30 * x) * x, 0, 2.0 * p.c20 + 6.0 * p.c30 * x, 0, 0


declare(
    Declaration(
        material=Yeoh,
        formula="c10 (I1b - 3) + c20 (I1b - 3)^2 + c30 (I1b - 3)^3 + k0/2 (ln J)^2",
        parameters="`c10`, `c20`, `c30`, `k0` (Pa)",
        default=Yeoh(c10=1200.0, c20=-200.0, c30=300.0, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("c10", m.c10), ("c20", m.c20), ("c30", m.c30)), m.k0
        ),
        order=80,
        ranges={"c10": (0.05, 20.0), "c20": (-0.5, 0.5), "c30": (0.0, 2.0), "k0": (0.05, 20.0)},
        examples={"Yeoh": Yeoh(c10=0.6, c20=-0.15, c30=0.2, k0=5.0)},
    )
)
