"""St Venant-Kirchhoff: W = lam/2 (tr E)^2 + mu tr(E^2)."""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import Material, check_lame
from mjed.materials.declaration import Declaration, declare
from mjed.terms import GreenLagrangeQuadratic, JPower, Term, TermGroup

__all__ = ["StVenantKirchhoff"]


@dataclass(frozen=True)
class StVenantKirchhoff(Material):
    """W = lam/2 (tr E)^2 + mu tr(E^2). One term with f = 1."""

    mu: float
    lam: float

    def __post_init__(self):
        check_lame(self, self.mu, self.lam)

    def decomposition(self):
        return (TermGroup((Term(JPower(0.0), GreenLagrangeQuadratic(self.mu, self.lam)),)),)


def energy(p, k):
    return 0.5 * p("lam") * k.tr(k.E) ** 2 + p("mu") * k.tr(k.E * k.E)


declare(
    Declaration(
        material=StVenantKirchhoff,
        formula="lam/2 (tr E)^2 + mu tr(E^2)",
        parameters="`mu`, `lam` (Pa)",
        default=StVenantKirchhoff(mu=3448.2759, lam=31034.483),  # E = 1e4, nu = 0.45
        energy=energy,
        volumetric=None,  # every term depends on E: nothing is a function of J alone
        volumetric_formula=None,
        classical=lambda m: forms.GreenLagrangeQuadratic(m.mu, m.lam),
        aliases=("stvk", "svk"),
        sofa=("StVenantKirchhoff", ("mu", "lam")),
        order=10,
        ranges={"mu": (0.05, 20.0), "lam": (0.05, 20.0)},
        examples={"StVenantKirchhoff": StVenantKirchhoff(mu=1.3, lam=2.1)},
    )
)
