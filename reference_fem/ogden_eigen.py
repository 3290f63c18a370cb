"""Sum of powers of the eigenvalues of a symmetric 3x3 UFL matrix, in closed form.

The Ogden energy needs S(C) = sum_i lambda_i^s over the eigenvalues lambda_i of C. UFL has
no eigenvalue operator, so they are written out with the trigonometric formula for a
symmetric 3x3 matrix (O. K. Smith, Comm. ACM 4(4), 1961):

    q = tr C / 3,  D = C - q I,  p = sqrt(tr(D^2) / 6),  r = det(D) / (2 p^3),
    phi = acos(r) / 3,
    lambda_1 = q + 2 p cos(phi),  lambda_3 = q + 2 p cos(phi + 2 pi / 3),
    lambda_2 = 3 q - lambda_1 - lambda_3.

S is a smooth function of C, but this formula is not differentiable where two eigenvalues
coincide (acos at r = +-1 has an infinite derivative; NaN at exactly r = +-1, and the
stiffness loses ~1e-17/gap of accuracy close to it). Two more branches cover those states:

* near-isotropic, |D|_F < 1e-3 q (rest state, small strains): the exact power series of the
  matrix function, sum_i f(q + d_i) = 3 f(q) + sum_{k>=2} f^(k)(q)/k! tr(D^k) (tr D = 0),
  truncated at k = 6 (truncation ~1e-21 in the value, ~1e-14 relative in the stiffness);
* near-double, t = 1 - |r| < 1e-6 (e.g. uniaxial or equibiaxial stretch): the simple
  eigenvalue lambda_s = q + 2 p sgn(r) c(t), with c(t) = cos(acos(1 - t)/3) replaced by its
  Taylor series in t (analytic at t = 0), and the pair lambda_s' = m +- d summed as an even
  series in d^2: f(m + d) + f(m - d) = sum_k 2 f^(2k)(m)/(2k)! d^(2k), where
  m = (3q - lambda_s)/2 and d^2 = m^2 - det C / lambda_s.

Every branch is written in three scalars, q, J2 = tr(D^2)/2 and J3 = det D (Cayley-Hamilton
gives tr(D^k) and det C from them): differentiating tr(D^6) directly made the stiffness form
take ~50 s to compile.
"""

from __future__ import annotations

import math

import ufl

__all__ = [
    "sum_of_eigenvalue_powers",
    "eigenvalues_sym3",
    "ISOTROPIC_SWITCH",
    "DOUBLE_SWITCH",
]

# |D|_F / q below which the isotropic power series replaces the trigonometric formula.
ISOTROPIC_SWITCH = 1e-3
# 1 - |r| below which the near-double-eigenvalue series replace it.
DOUBLE_SWITCH = 1e-6
# Highest power of D kept in the isotropic series.
_ISO_ORDER = 6
# Taylor coefficients of c(t) = cos(acos(1 - t) / 3) (the root of 4c^3 - 3c = 1 - t near 1).
_C_SERIES = (1.0, -1.0 / 9.0, -4.0 / 243.0, -28.0 / 6561.0, -80.0 / 59049.0)
# Highest power of d^2 kept in the pair series.
_PAIR_ORDER = 4


def _invariants(C):
    """Q = tr C / 3, and J2 = tr(D^2)/2, J3 = det D of the deviator D = C - q I."""
    q = ufl.tr(C) / 3.0
    D = C - q * ufl.Identity(3)
    return q, 0.5 * ufl.inner(D, D), ufl.det(D)


def _power_sums(J2, J3, order: int) -> dict:
    """tr(D^k), k = 2..order, of a traceless 3x3 D from J2 and J3.

    Cayley-Hamilton for traceless D gives D^3 = J2 D + J3 I, hence the Newton recursion
    p_k = J2 p_(k-2) + J3 p_(k-3) with p_0 = 3, p_1 = 0, p_2 = 2 J2, p_3 = 3 J3.
    """
    p = {0: 3.0, 1: 0.0, 2: 2.0 * J2, 3: 3.0 * J3}
    for k in range(4, order + 1):
        p[k] = J2 * p[k - 2] + J3 * p[k - 3]
    return {k: v for k, v in p.items() if 2 <= k <= order}


def _binomial(s, k: int):
    """Generalised binomial coefficient s (s-1) ... (s-k+1) / k! (s a float or UFL scalar)."""
    out = 1.0
    for j in range(k):
        out = out * (s - j) / (j + 1)
    return out


def _trig_eigenvalues(q, p, r):
    phi = ufl.acos(r) / 3.0
    lam1 = q + 2.0 * p * ufl.cos(phi)
    lam3 = q + 2.0 * p * ufl.cos(phi + 2.0 * math.pi / 3.0)
    return lam1, 3.0 * q - lam1 - lam3, lam3


def eigenvalues_sym3(C):
    """The eigenvalues (lambda_1 >= lambda_2 >= lambda_3) of a symmetric 3x3 UFL matrix.

    Trigonometric formula only: differentiable for distinct eigenvalues; NaN where C is a
    multiple of the identity.
    """
    q, J2, J3 = _invariants(C)
    p = ufl.sqrt(J2 / 3.0)
    r = ufl.max_value(ufl.min_value(J3 / (2.0 * p**3), 1.0), -1.0)  # rounding can exceed 1
    return _trig_eigenvalues(q, p, r)


def _isotropic_series(q, J2, J3, s):
    total = 3.0 * q**s
    for k, trace in _power_sums(J2, J3, _ISO_ORDER).items():
        total = total + _binomial(s, k) * q ** (s - k) * trace
    return total


def _double_series(q, J2, J3, p, r, s):
    sgn = ufl.conditional(ufl.gt(r, 0.0), 1.0, -1.0)  # which end: r = +1 or r = -1
    t = 1.0 - sgn * r
    c = sum(a * t**k for k, a in enumerate(_C_SERIES))
    lam_s = q + 2.0 * p * sgn * c  # the simple eigenvalue
    m = 0.5 * (3.0 * q - lam_s)  # mean of the pair
    det_C = q**3 - q * J2 + J3
    d2 = m**2 - det_C / lam_s  # half the pair's gap, squared
    pair = sum(2.0 * _binomial(s, 2 * k) * m ** (s - 2 * k) * d2**k for k in range(_PAIR_ORDER + 1))
    return lam_s**s + pair


def sum_of_eigenvalue_powers(C, s):
    """sum_i lambda_i(C)^s for a symmetric positive definite 3x3 UFL matrix C.

    Exact to rounding up to second derivatives for any eigenvalue multiplicity (see the
    module docstring for the three branches and their switches).

    Args:
        C: symmetric positive definite 3x3 UFL expression.
        s: the exponent (alpha/2 for Ogden), a float or a UFL scalar (e.g. a Constant).

    Returns:
        scalar UFL expression.
    """
    q, J2, J3 = _invariants(C)
    switch2 = (ISOTROPIC_SWITCH * q) ** 2  # compared with |D|_F^2 = 2 J2
    # The floor only matters where the isotropic branch is selected; it keeps the others
    # finite there (p = 0 would give r = 0/0).
    p = ufl.sqrt(ufl.max_value(J2, 0.5 * switch2) / 3.0)
    r = J3 / (2.0 * p**3)
    # Likewise, clamping r keeps acos and its derivative finite where the trigonometric
    # branch is not selected (|r| > 1 - DOUBLE_SWITCH), including |r| > 1 from rounding.
    bound = 1.0 - 0.5 * DOUBLE_SWITCH
    trig = sum(
        li**s for li in _trig_eigenvalues(q, p, ufl.max_value(ufl.min_value(r, bound), -bound))
    )
    return ufl.conditional(
        ufl.lt(2.0 * J2, switch2),
        _isotropic_series(q, J2, J3, s),
        ufl.conditional(
            ufl.gt(abs(r), 1.0 - DOUBLE_SWITCH), _double_series(q, J2, J3, p, r, s), trig
        ),
    )
