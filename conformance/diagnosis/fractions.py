"""Simple fractions in the diagnosis's words: a fitted factor that is 1/2, -2/3 or 3 is said as
one (the mistake it points to is a dropped half, an isochoric power, a tripled term), any other
number as a decimal. One helper so every reading rounds the same way.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Optional

__all__ = ["simple_fraction", "written_number"]


def simple_fraction(x: float, denominator: int, rtol: float) -> Optional[Fraction]:
    """X as the nearest fraction with a denominator of at most ``denominator``, when that is
    within rtol * max(1, |x|) of x; None otherwise.
    """
    q = Fraction(x).limit_denominator(denominator)
    return q if abs(float(q) - x) <= rtol * max(1.0, abs(x)) else None


def written_number(x: float, rtol: float = 1e-9, digits: int = 4, denominator: int = 12) -> str:
    """X written as a fraction ("-2/3", "3") when it is one (see :func:`simple_fraction`), else
    to ``digits`` significant digits.
    """
    q = simple_fraction(x, denominator, rtol)
    return str(q) if q is not None else f"{x:.{digits}g}"
