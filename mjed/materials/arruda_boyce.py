"""Arruda-Boyce, the five-term 8-chain series:
W = mu sum_i c_i N^(1-i) (I1b^i - 3^i) + k0/2 (ln J)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import Material, log_squared, require_positive
from mjed.materials.declaration import Declaration, declare
from mjed.terms import I1Power, JPower, LogPolynomial, Term, TermGroup, Unity

__all__ = ["ArrudaBoyce", "ARRUDA_BOYCE_COEFFICIENTS"]

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


def energy(p, k):
    N = p("N")
    series = sum(
        c * N ** (1 - i) * (k.I1b**i - 3.0**i)
        for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)
    )
    return p("mu") * series + 0.5 * p("k0") * k.lnJ**2


def psi(p, I1b, I2b, m):
    """The isochoric part and its derivatives by I1b (for the classical element): with
    a_i = mu c_i N^(1-i), Psi = sum a_i (I1b^i - 3^i), Psi_1 = sum i a_i I1b^(i-1),
    Psi_11 = sum i (i-1) a_i I1b^(i-2).
    """
    a = [p.mu * c * p.N ** (1 - i) for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)]
    powers = [1.0, I1b, I1b * I1b]
    powers += [
        powers[2] * I1b,
        powers[2] * powers[2],
        powers[2] * powers[2] * I1b,
    ]  # I1b^0 .. I1b^5
    W = sum(a[i - 1] * powers[i] for i in range(1, 6)) - sum(a[i - 1] * 3.0**i for i in range(1, 6))
    p1 = a[0] + sum(i * a[i - 1] * powers[i - 1] for i in range(2, 6))
    p11 = 2.0 * a[1] + sum(i * (i - 1) * a[i - 1] * powers[i - 2] for i in range(3, 6))
    return W, p1, 0, p11, 0, 0


declare(
    Declaration(
        material=ArrudaBoyce,
        formula="mu sum_{i=1..5} c_i N^(1-i) (I1b^i - 3^i) + k0/2 (ln J)^2",
        notes="`c = (1/2, 1/20, 11/1050, 19/7000, 519/673750)`",
        parameters="`mu`, `k0` (Pa), `N` (dimensionless, default 8)",
        default=ArrudaBoyce(mu=2500.0, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        classical=lambda m: forms.Decoupled(
            forms.IsochoricPsi(psi), (("mu", m.mu), ("N", m.N)), m.k0
        ),
        aliases=("ab",),
        sofa=("ArrudaBoyce", ("mu", "k0")),
        order=50,
        ranges={"mu": (0.05, 20.0), "k0": (0.05, 20.0), "N": (2.0, 20.0)},
        examples={"ArrudaBoyce": ArrudaBoyce(mu=1.0, k0=5.0)},
    )
)
