"""Ogden (one term): W = mu/alpha^2 (J^(-alpha/3) sum_i lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2,
lambda_i the eigenvalues of C.
"""

from __future__ import annotations

from dataclasses import dataclass

from mjed.materials import classical_forms as forms
from mjed.materials.base import Material, log_squared, require_finite, require_positive
from mjed.materials.declaration import Declaration, declare
from mjed.terms import JPower, LogPolynomial, Term, TermGroup, Unity

__all__ = ["Ogden"]


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


def energy(p, k):
    if p.value("alpha") == 0.0:
        raise ValueError("Ogden: parameter alpha must be non-zero")
    mu, alpha = p("mu"), p("alpha")
    # sum_i lambda_i^(alpha/2) over the eigenvalues lambda_i of C (= principal stretches^alpha)
    stretch_sum = k.eigenvalue_power_sum(k.C, 0.5 * alpha)
    return mu / alpha**2 * (k.J ** (-alpha / 3.0) * stretch_sum - 3.0) + 0.5 * p("k0") * k.lnJ**2


declare(
    Declaration(
        material=Ogden,
        formula="mu / alpha^2 (J^(-alpha/3) sum_i lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2",
        notes="`lambda_i` the eigenvalues of `C` (one term)",
        parameters="`mu`, `k0` (Pa), `alpha` (dimensionless, non-zero)",
        default=Ogden(mu=5000.0, alpha=3.0, k0=3.0e4),
        energy=energy,
        volumetric=log_squared,
        volumetric_formula="k0/2 (ln J)^2",
        # the ``tangent`` option is the engine's: the classical law is always the exact Hessian
        classical=lambda m: forms.SpectralOgden(m.mu, m.alpha, m.k0),
        sofa=("Ogden", ("mu", "alpha", "k0")),
        order=70,
        ranges={"mu": (0.05, 20.0), "alpha": [-4.0, -2.0, 1.5, 2.0, 3.0, 5.0], "k0": (0.05, 20.0)},
        # OgdenNegative: a negative alpha changes the kernel
        examples={
            "Ogden": Ogden(mu=1.0, alpha=3.0, k0=5.0),
            "OgdenNegative": Ogden(mu=1.0, alpha=-2.0, k0=5.0),
        },
    )
)
