"""What every material shares: parameter validation and the term-group interface."""

from __future__ import annotations

import math
from typing import Tuple

from mjed.terms import JPower, TermGroup

__all__ = [
    "Material",
    "require_finite",
    "require_positive",
    "check_lame",
    "ISOCHORIC_I1",
    "ISOCHORIC_I2",
    "log_squared",
]

#: f(J) of the isochoric invariants: I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2.
ISOCHORIC_I1 = JPower(-2.0 / 3.0)
ISOCHORIC_I2 = JPower(-4.0 / 3.0)


class Material:
    """Base of the material dataclasses.

    Subclasses are frozen dataclasses of their parameters; ``decomposition()`` returns the MJED
    term groups of the strain energy density (per unit rest volume), zero at rest.
    """

    def decomposition(self) -> Tuple[TermGroup, ...]:
        raise NotImplementedError

    @property
    def name(self) -> str:
        return type(self).__name__


def require_finite(obj, *names: str) -> None:
    """Raise ValueError naming the first parameter that is not a finite real number."""
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(
                f"{type(obj).__name__}: parameter {n} must be a finite real number, got {v!r}"
            )


def require_positive(obj, *names: str) -> None:
    """Raise ValueError naming the first parameter that is not finite and > 0."""
    require_finite(obj, *names)
    for n in names:
        if getattr(obj, n) <= 0:
            raise ValueError(
                f"{type(obj).__name__}: parameter {n} must be > 0, got {getattr(obj, n)!r}"
            )


def check_lame(obj, mu: float, lam: float) -> None:
    """Mu > 0 and a positive bulk modulus lam + 2 mu / 3."""
    require_positive(obj, "mu")
    require_finite(obj, "lam")
    if 3.0 * lam + 2.0 * mu <= 0:
        raise ValueError(
            f"{type(obj).__name__}: parameter lam must give a positive bulk modulus "
            f"lam + 2 mu/3, got lam={lam!r}"
        )


def log_squared(p, k):
    """The oracle's k0/2 (ln J)^2, the volumetric energy of most isochoric laws (written
    against a formula namespace, see mjed.materials.declaration).
    """
    return 0.5 * p("k0") * k.lnJ**2
