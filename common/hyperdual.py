"""Hyper-dual numbers: exact first and second derivatives of a formula in one evaluation.

A hyper-dual number a + b e1 + c e2 + d e1 e2 (e1^2 = e2^2 = 0) carried through a formula gives
its value (a), its derivatives along the two seeded directions (b, c) and the mixed second
derivative (d), to round-off, with no step to choose. The parts are NumPy arrays of one shape
(one value per cell, say), so a formula is differentiated over all cells at once. Used where a
declared energy formula is differentiated without compiling it: the diagnosis's pieces of a
decoupled energy (conformance.diagnosis.split_parts) and the tests' engines.
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["HD", "exp", "ln", "sqrt"]


class HD:
    """A hyper-dual array a + b e1 + c e2 + d e1 e2 (e1^2 = e2^2 = 0), parts of one shape."""

    __slots__ = ("a", "b", "c", "d")
    __array_ufunc__ = None  # ndarray * HD defers to HD.__rmul__ instead of an object array

    def __init__(self, a, b=0.0, c=0.0, d=0.0):
        self.a, self.b, self.c, self.d = a, b, c, d

    def apply(self, g, dg, d2g) -> "HD":
        """g(self) from g, g' and g'' at self.a: the chain rule to second order,
        d(g(x))/de1 de2 = g' d + g'' b c.
        """
        return HD(g, dg * self.b, dg * self.c, dg * self.d + d2g * self.b * self.c)

    def __add__(self, o):
        if isinstance(o, HD):
            return HD(self.a + o.a, self.b + o.b, self.c + o.c, self.d + o.d)
        return HD(self.a + o, self.b, self.c, self.d)

    __radd__ = __add__

    def __neg__(self):
        return HD(-self.a, -self.b, -self.c, -self.d)

    def __sub__(self, o):
        return self + (-o)

    def __rsub__(self, o):
        return (-self) + o

    def __mul__(self, o):
        if isinstance(o, HD):
            return HD(
                self.a * o.a,
                self.a * o.b + self.b * o.a,
                self.a * o.c + self.c * o.a,
                self.a * o.d + self.b * o.c + self.c * o.b + self.d * o.a,
            )
        if not isinstance(o, (numbers.Number, np.ndarray)):
            return NotImplemented  # e.g. a matrix of hyper-duals, which multiplies itself
        return HD(self.a * o, self.b * o, self.c * o, self.d * o)

    __rmul__ = __mul__

    def reciprocal(self) -> "HD":
        r = 1.0 / self.a
        return self.apply(r, -r * r, 2.0 * r * r * r)

    def __truediv__(self, o):
        return self * (o.reciprocal() if isinstance(o, HD) else 1.0 / o)

    def __rtruediv__(self, o):
        return self.reciprocal() * o

    def __pow__(self, p: float):
        p = float(p)
        return self.apply(self.a**p, p * self.a ** (p - 1.0), p * (p - 1.0) * self.a ** (p - 2.0))


def exp(x):
    """e^x for a hyper-dual or a plain number or array."""
    if not isinstance(x, HD):
        return np.exp(x)
    e = np.exp(x.a)
    return x.apply(e, e, e)


def ln(x):
    """The natural logarithm of a hyper-dual or a plain number or array."""
    if not isinstance(x, HD):
        return np.log(x)
    return x.apply(np.log(x.a), 1.0 / x.a, -1.0 / (x.a * x.a))


def sqrt(x):
    """The square root of a hyper-dual or a plain number or array."""
    return x**0.5 if isinstance(x, HD) else np.sqrt(x)
