"""Compressible Neo-Hookean: W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 (not isochoric)."""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import Material, check_lame
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, JPower, LogPolynomial, Term, TermGroup, Unity

__all__ = ["NeoHookean"]


@dataclass(frozen=True)
class NeoHookean(Material):
    """W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 (compressible, not isochoric)."""

    mu: float
    lam: float

    def __post_init__(self):
        check_lame(self, self.mu, self.lam)

    def decomposition(self):
        mu, lam = self.mu, self.lam
        # the constant -3 mu/2 that makes W = 0 at rest sits in f(J) of the volumetric term
        return (
            TermGroup(
                (
                    Term(JPower(0.0), I1Power(0.5 * mu)),
                    Term(LogPolynomial(0.5 * lam, -mu, -1.5 * mu), Unity()),
                )
            ),
        )


def energy(p, k):
    mu = p("mu")
    return 0.5 * mu * (k.I1 - 3.0) - mu * k.lnJ + 0.5 * p("lam") * k.lnJ**2


def volumetric(p, k):
    return -p("mu") * k.lnJ + 0.5 * p("lam") * k.lnJ**2


declare(
    Declaration(
        material=NeoHookean,
        formula="mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2",
        parameters="`mu`, `lam` (Pa)",
        default=NeoHookean(mu=3448.2759, lam=31034.483),
        energy=energy,
        volumetric=volumetric,
        volumetric_formula="-mu ln J + lam/2 (ln J)^2",
        classical=lambda m: forms.CompressibleNeoHookean(m.mu, m.lam),
        aliases=("nh",),
        sofa=("NeoHookean", ("mu", "lam")),
        order=20,
        ranges={"mu": (0.05, 20.0), "lam": (0.05, 20.0)},
        examples={"NeoHookean": NeoHookean(mu=1.3, lam=2.1)},
    )
)
