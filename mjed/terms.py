"""The vocabulary of MJED terms (paper, eq. 2).

A strain energy density is written as

    W = sum_groups c_w * sum_{k in w} f_k(J) g_k(C)          (plain group)
      + sum_groups c_w * phi_w(sum_{k in w} f_k(J) g_k(C))   (smooth function of the sum)

with phi_w one of :class:`Exp` (e^u), :class:`Log` (ln(a + u)) or :class:`Power`
((a + u)^p): a smooth function of a separable sum, whose Hessian is phi' times the sum's
plus the rank-one phi'' du (x) du.

A :class:`Term` pairs a function of J (:class:`JFunction`, which gives f, f', f'') with a
function of C (:class:`InvariantFunction`, which gives g, S = 2 dg/dC and dS/dC). The
derivative of S is declared as a list of :class:`TangentPair`:

    dS/dC : H = sum_first beta (A : H) A + sum_second gamma B H B,

with the matrices A, B known when the material is built (so the engine can precompute their
products with the shape vectors) and the scalars beta, gamma evaluated at each state.
Adding a material means composing these pieces; the engine never changes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Literal, Optional, Sequence, Tuple, Union

import numpy as np

from mjed.kinematics import Kinematics

__all__ = [
    "IDENTITY",
    "JFunction",
    "JPower",
    "LogPolynomial",
    "JLogJ",
    "InvariantFunction",
    "TangentPair",
    "Unity",
    "I1Power",
    "LinearI2",
    "GreenLagrangeQuadratic",
    "Term",
    "SmoothFunction",
    "Exp",
    "Log",
    "Power",
    "TermGroup",
]

IDENTITY = np.eye(3)
IDENTITY.setflags(write=False)

Scalar = Union[float, np.ndarray]


# --------------------------------------------------------------------------- functions of J
class JFunction(ABC):
    """A scalar function of the volume ratio and its first two derivatives."""

    @abstractmethod
    def __call__(self, J: np.ndarray) -> Tuple[Scalar, Scalar, Scalar]:
        """Return f(J), f'(J), f''(J), each (m,) or a float."""


@dataclass(frozen=True)
class JPower(JFunction):
    """f = J^p; p = 0 is the constant 1 (terms without a J factor)."""

    p: float

    def __call__(self, J):
        p = self.p
        if p == 0.0:
            return 1.0, 0.0, 0.0
        Jp2 = J ** (p - 2.0)
        return Jp2 * J * J, p * Jp2 * J, p * (p - 1.0) * Jp2


@dataclass(frozen=True)
class LogPolynomial(JFunction):
    """f = a2 (ln J)^2 + a1 ln J + a0: the volumetric terms of the ln J family."""

    a2: float
    a1: float = 0.0
    a0: float = 0.0

    def __call__(self, J):
        L = np.log(J)
        f = (self.a2 * L + self.a1) * L + self.a0
        df = (2.0 * self.a2 * L + self.a1) / J
        d2f = (2.0 * self.a2 * (1.0 - L) - self.a1) / (J * J)
        return f, df, d2f


@dataclass(frozen=True)
class JLogJ(JFunction):
    """f = k (J ln J - J + 1) + c: Costa's volumetric term."""

    k: float
    c: float = 0.0

    def __call__(self, J):
        L = np.log(J)
        return self.k * (J * L - J + 1.0) + self.c, self.k * L, self.k / J


# --------------------------------------------------------------------- functions of C
@dataclass(frozen=True, eq=False)
class TangentPair:
    """One piece of dS/dC : H.

    kind "first": beta (A : H) A.  kind "second": gamma B H B.
    matrix: symmetric (3, 3) constant, or (m, 3, 3) with one constant matrix per cell.

    kind "spectral": sum_{n,l} theta_nl P_n H P_l with P_n = v_n v_n^T the eigenprojectors of
    C (from Kinematics.eig); its coefficient is theta, (m, 3, 3) and symmetric. This is the
    form of the exact derivative of a matrix power C^p, which no constant A or B can give.
    """

    kind: Literal["first", "second", "spectral"]
    matrix: np.ndarray = field(default_factory=lambda: IDENTITY)


class InvariantFunction(ABC):
    """g(C) with S = 2 dg/dC and dS/dC in MJED's (beta, A) / (gamma, B) form."""

    #: the (kind, matrix) of each tangent pair; the coefficients come from tangent_coefficients.
    tangent: Tuple[TangentPair, ...] = ()

    @abstractmethod
    def value(self, kin: Kinematics) -> Scalar:
        """g, (m,) or a float."""

    def stress(self, kin: Kinematics) -> Union[np.ndarray, None]:
        """S = 2 dg/dC, (m, 3, 3), or a (3, 3) constant when it is the same in every cell;
        None when g does not depend on C.
        """
        if type(self).stress_t is InvariantFunction.stress_t:
            return None  # neither form overridden: g does not depend on C
        S = self.stress_t(kin)
        return S if S is None or S.ndim == 2 else np.ascontiguousarray(np.moveaxis(S, -1, 0))

    def stress_t(self, kin: Kinematics) -> Union[np.ndarray, None]:
        """S component-major, (3, 3, m), or a (3, 3) constant; None when g does not depend on C.

        This is what the engine reads. Override it instead of ``stress`` when S is naturally
        formed component-major (the engine then skips a copy per term); by default it
        converts ``stress``.
        """
        if type(self).stress is InvariantFunction.stress:
            return None
        S = self.stress(kin)
        return S if S is None or S.ndim == 2 else np.ascontiguousarray(np.moveaxis(S, 0, -1))

    def tangent_coefficients(self, kin: Kinematics) -> Sequence[Scalar]:
        """Beta or gamma for each entry of ``tangent``, each (m,) or a float."""
        return ()


class Unity(InvariantFunction):
    """g = 1: the term is a pure function of J (volumetric terms)."""

    def value(self, kin):
        return 1.0

    def __eq__(self, other):
        return isinstance(other, Unity)

    def __hash__(self):
        return hash(Unity)


def _scaled_identity_t(s, m: int) -> np.ndarray:
    """S Id per cell, component-major (3, 3, m); s (m,) or a float."""
    out = np.zeros((3, 3, m))
    for i in range(3):
        out[i, i] = s
    return out


@dataclass(frozen=True)
class I1Power(InvariantFunction):
    """g = c I1^n (n >= 1): S = 2 c n I1^(n-1) Id; dS/dC : H = 2 c n (n-1) I1^(n-2) tr(H) Id."""

    c: float
    n: int = 1

    def __post_init__(self):
        object.__setattr__(self, "tangent", (TangentPair("first"),) if self.n >= 2 else ())

    def value(self, kin):
        return self.c * kin.I1**self.n

    def stress_t(self, kin):
        if self.n == 1:  # 2 c Id, the same in every cell
            return 2.0 * self.c * IDENTITY
        return _scaled_identity_t(2.0 * self.c * self.n * kin.I1 ** (self.n - 1), kin.m)

    def tangent_coefficients(self, kin):
        if self.n < 2:
            return ()
        return (2.0 * self.c * self.n * (self.n - 1) * kin.I1 ** (self.n - 2),)


@dataclass(frozen=True)
class LinearI2(InvariantFunction):
    """g = c I2: S = 2c (I1 Id - C); dS/dC : H = 2c tr(H) Id - 2c H."""

    c: float
    tangent = (TangentPair("first"), TangentPair("second"))

    def value(self, kin):
        return self.c * kin.I2

    def stress_t(self, kin):
        S = np.multiply(kin.C_t, -2.0 * self.c)
        t = 2.0 * self.c * kin.I1
        for i in range(3):
            S[i, i] += t
        return S

    def tangent_coefficients(self, kin):
        return (2.0 * self.c, -2.0 * self.c)


@dataclass(frozen=True)
class GreenLagrangeQuadratic(InvariantFunction):
    """g = lam/2 (tr E)^2 + mu tr(E^2): S = lam tr(E) Id + 2 mu E; dS/dC : H = lam/2 tr(H) Id +
    mu H.
    """

    mu: float
    lam: float
    tangent = (TangentPair("first"), TangentPair("second"))

    def value(self, kin):
        E = kin.E_t.reshape(9, -1)
        trE = kin.trE
        return 0.5 * self.lam * trE**2 + self.mu * np.einsum("km,km->m", E, E)

    def stress_t(self, kin):
        S = np.multiply(kin.E_t, 2.0 * self.mu)
        t = self.lam * kin.trE
        for i in range(3):
            S[i, i] += t
        return S

    def tangent_coefficients(self, kin):
        return (0.5 * self.lam, self.mu)


# ----------------------------------------------------------------------------- terms
@dataclass(frozen=True)
class Term:
    """f(J) g(C)."""

    f: JFunction
    g: InvariantFunction


class SmoothFunction(ABC):
    """phi(u) of a group's sum u, applied per cell."""

    @abstractmethod
    def __call__(self, u: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """phi(u), phi'(u), phi''(u), each (m,) like u."""


@dataclass(frozen=True)
class Exp(SmoothFunction):
    """phi = e^u (a shift would only scale the group's coefficient)."""

    def __call__(self, u):
        e = np.exp(u)
        return e, e, e


@dataclass(frozen=True)
class Log(SmoothFunction):
    """phi = ln(shift + u); defined for shift + u > 0 (NaN beyond, as ln J for J <= 0)."""

    shift: float = 0.0

    def __call__(self, u):
        a = self.shift + u
        inv = 1.0 / a
        if not np.all(a > 0.0):  # outside the domain the derivatives are NaN too, like ln itself
            inv = np.where(a > 0.0, inv, np.nan)
        with np.errstate(invalid="ignore"):
            return np.log(a), inv, -inv * inv


@dataclass(frozen=True)
class Power(SmoothFunction):
    """phi = (shift + u)^p for real p (shift + u > 0 unless p is an integer)."""

    p: float
    shift: float = 0.0

    def __call__(self, u):
        a = self.shift + u
        ap2 = a ** (self.p - 2.0)
        return ap2 * a * a, self.p * ap2 * a, self.p * (self.p - 1.0) * ap2


@dataclass(frozen=True)
class TermGroup:
    """Terms whose products are summed into u; the group contributes c u (plain) or
    c phi(u) with ``function`` phi. ``exponential=True`` is the same as function=Exp().
    """

    terms: Tuple[Term, ...]
    exponential: bool = False
    coefficient: float = 1.0
    function: Optional[SmoothFunction] = None

    def __post_init__(self):
        if self.exponential and self.function not in (None, Exp()):
            raise ValueError(f"TermGroup: exponential=True contradicts function={self.function!r}")
        if self.function is not None and not isinstance(self.function, SmoothFunction):
            raise TypeError(f"TermGroup: function must be a SmoothFunction, got {self.function!r}")
        if self.exponential:
            object.__setattr__(self, "function", Exp())
        elif self.function == Exp():
            object.__setattr__(self, "exponential", True)

    @property
    def plain(self) -> bool:
        """The group contributes c u (no function of the sum)."""
        return self.function is None
