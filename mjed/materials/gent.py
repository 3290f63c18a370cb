"""Gent: W = -mu Jm/2 ln(1 - (I1b - 3)/Jm) + k0/2 (ln J)^2, locking as I1b - 3 approaches Jm."""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import ISOCHORIC_I1, Material, log_squared, require_positive
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, Log, LogPolynomial, Term, TermGroup, Unity

__all__ = ["Gent"]


@dataclass(frozen=True)
class Gent(Material):
    """W = -mu Jm/2 ln(1 - (I1b - 3)/Jm) + k0/2 (ln J)^2.

    The logarithm is one group c ln(a + u) of the separable sum u = -J^(-2/3) I1 / Jm, with
    a = 1 + 3/Jm and c = -mu Jm/2. The energy is finite only while I1b - 3 < Jm (the chains'
    limiting extensibility); beyond it W, its force and its stiffness are NaN. Valid
    parameters: mu > 0 (the initial shear modulus), Jm > 0, k0 > 0.
    """

    mu: float
    Jm: float
    k0: float

    def __post_init__(self):
        require_positive(self, "mu", "Jm", "k0")

    def decomposition(self):
        mu, Jm = self.mu, self.Jm
        return (
            TermGroup(
                (Term(ISOCHORIC_I1, I1Power(-1.0 / Jm)),),
                coefficient=-0.5 * mu * Jm,
                function=Log(1.0 + 3.0 / Jm),
            ),
            TermGroup((Term(LogPolynomial(0.5 * self.k0), Unity()),)),
        )


def energy(p, k):
    mu, Jm = p("mu"), p("Jm")
    return -0.5 * mu * Jm * k.ln(1.0 - (k.I1b - 3.0) / Jm) + 0.5 * p("k0") * k.lnJ**2


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b (for the classical element):
    d = 1 - (I1b - 3)/Jm, Psi_1 = mu / (2 d), Psi_11 = mu / (2 Jm d^2).
    """
    d = 1.0 - (I1b - 3.0) / p.Jm
    p1 = 0.5 * p.mu / d
    return -0.5 * p.mu * p.Jm * m.log(d), p1, 0, p1 / (p.Jm * d), 0, 0


declare(
    Declaration(
        material=Gent,
        formula="-mu Jm/2 ln(1 - (I1b - 3)/Jm) + k0/2 (ln J)^2",
        notes="finite for `I1b - 3 < Jm`",
        parameters="`mu`, `k0` (Pa), `Jm` (dimensionless)",
        default=Gent(mu=2500.0, Jm=10.0, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("mu", m.mu), ("Jm", m.Jm)), m.k0
        ),
        order=90,
        ranges={"mu": (0.05, 20.0), "Jm": (10.0, 100.0), "k0": (0.05, 20.0)},
        # Jm above the largest I1b - 3 the test states reach (about 20, on the perturbed box of
        # test_engine_modules), close enough that the logarithm bends (1 - (I1b - 3)/Jm to 0.3);
        # beyond it Gent is undefined, by design
        examples={"Gent": Gent(mu=1.2, Jm=30.0, k0=5.0)},
    )
)
