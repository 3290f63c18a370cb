"""What every material shares: parameter validation and the term-group interface."""

from __future__ import annotations

import math
from typing import Tuple

from mjed.terms import TermGroup

__all__ = ["Material", "require_finite", "require_positive"]


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
