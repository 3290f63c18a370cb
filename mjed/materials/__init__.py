"""Hyperelastic materials, each declared as its MJED terms.

Every material is a frozen dataclass of its parameters, validated on construction, with a
``decomposition()`` method returning its term groups (see :mod:`mjed.terms`). The strain
energies (zero at rest) are:

    StVenantKirchhoff   lam/2 (tr E)^2 + mu tr(E^2)
    NeoHookean          mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2
    MooneyRivlin        c1 (I1b - 3) + c2 (I2b - 3) + k0/2 (ln J)^2
    VerondaWestmann     c1 (exp(c2 (I1b - 3)) - 1) - c1 c2/2 (I2b - 3) + k0/2 (ln J)^2
    ArrudaBoyce         mu sum_i c_i N^(1-i) (I1b^i - 3^i) + k0/2 (ln J)^2
    Costa               a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum B_ij (R^T E R)_ij^2
    Ogden               mu/alpha^2 (J^(-alpha/3) sum_i lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2
"""

from mjed.materials.anisotropic import Costa
from mjed.materials.base import Material
from mjed.materials.isotropic import (
    ARRUDA_BOYCE_COEFFICIENTS,
    ArrudaBoyce,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    StVenantKirchhoff,
    VerondaWestmann,
)
from mjed.materials.sofa import from_sofa

__all__ = [
    "Material",
    "StVenantKirchhoff",
    "NeoHookean",
    "MooneyRivlin",
    "VerondaWestmann",
    "ArrudaBoyce",
    "Costa",
    "Ogden",
    "from_sofa",
    "ARRUDA_BOYCE_COEFFICIENTS",
]
