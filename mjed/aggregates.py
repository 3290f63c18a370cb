"""Term aggregation: a material's term groups folded into the sums the engine needs.

For one group with u = sum_k f_k g_k (paper, eqs. 3-4):

    S-bar = sum_k f_k S_k,  S-hat = sum_k f'_k S_k,  h = sum_k f'_k g_k,  g2 = sum_k f''_k g_k,

and, per declared tangent pair, the weight sum_k f_k beta_k (or gamma_k). A plain group
contributes c u, a group with a smooth function phi (e^u, ln(a + u), (a + u)^p) c phi(u).
Everything in the Hessian but the rank-one term c phi''(u) du (x) du of such a group is
linear in these sums, so all groups are folded into one :class:`Aggregates` record (each
weighted by c or c phi'(u)) before any 3x3 algebra.
Sums that no term feeds stay None, so e.g. St Venant-Kirchhoff (f = 1) never builds the
volumetric coupling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, Hashable, Mapping, Optional, Sequence, Tuple

import numpy as np

from mjed.cellwise import is_zero
from mjed.kinematics import Kinematics
from mjed.terms import TangentPair, Term, TermGroup

__all__ = ["slot_key", "add_stress", "GroupSums", "Aggregates", "fold_groups"]


def slot_key(pair: TangentPair) -> Tuple[str, Hashable]:
    """The key shared by all tangent pairs with the same kind and the same constant matrix
    (per-cell matrices are keyed by identity).
    """
    if pair.kind == "spectral":
        return pair.kind, None
    m = pair.matrix
    if m.ndim == 2:
        return pair.kind, m.tobytes()
    return pair.kind, id(m)


def add_optional(acc, value):
    """Acc + value where None stands for zero (so absent terms cost nothing)."""
    if value is None:
        return acc
    return value if acc is None else acc + value


def add_stress(acc, value):
    """Acc + value for stresses, None standing for zero: each is component-major (3, 3, m) or
    a constant (3, 3) matrix. A constant added to a per-cell stress is broadcast over the
    cells (NumPy alone would align (3, 3) with the trailing (3, m) axes: an error, or for
    m = 3 a silently wrong sum).
    """
    if value is None:
        return acc
    if acc is None:
        return value
    if np.ndim(acc) == 2 and np.ndim(value) == 3:
        acc = acc[:, :, None]
    elif np.ndim(acc) == 3 and np.ndim(value) == 2:
        value = value[:, :, None]
    return acc + value


def scale(s, A):
    """S * A for a stress: s per cell, (m,) or scalar, and A component-major (3, 3, m), a
    constant (3, 3) matrix or a scalar. A scale of exactly 1.0 returns A itself (no copy:
    the product would be A).
    """
    if np.ndim(s) == 0:
        return A if (s == 1.0 and np.ndim(A) > 0) else s * A
    if np.ndim(A) == 2:  # a constant matrix, the same in every cell
        return A[:, :, None] * s
    return s * A


def scale_weight(s, w):
    """S * w for a tangent weight: s per cell, (m,) or scalar, and w (m,), a float or, for a
    spectral pair, (m, 3, 3) cell-major.
    """
    if np.ndim(s) == 0 or np.ndim(w) <= 1:
        return s * w
    return np.reshape(s, np.shape(s) + (1,) * (np.ndim(w) - 1)) * w


def scale_optional(s, A):
    return None if A is None else scale(s, A)


class GroupSums:
    """Running sums of one group's terms: u, S-bar, h and, for the stiffness only (``tangent``),
    S-hat, g2 and the tangent weights.
    """

    def __init__(self, m: int, tangent: bool = True, value: bool = True):
        self.m = m
        self.tangent = tangent
        self.value = value  # u is wanted (the energy, or phi(u) of a non-plain group)
        self.u = np.zeros(m)
        self.S = None
        self.S_hat = None
        self.h = None
        self.g2 = None
        self.pair_weights: Dict[Tuple[str, Hashable], object] = {}

    def add(self, term: Term, kin: Kinematics, J: np.ndarray) -> None:
        f, df, d2f = term.f(J)
        # g itself feeds u, h = f' g and g2 = f'' g; a term whose f is constant (f' = f'' = 0)
        # needs it only for u, which the force alone does not (St Venant-Kirchhoff, Neo-Hookean).
        if self.value or not is_zero(df) or (self.tangent and not is_zero(d2f)):
            g = term.g.value(kin)
            if self.value:
                self.u += f * g
            if not is_zero(df) and not is_zero(g):
                self.h = add_optional(self.h, df * g)
        Sk = term.g.stress_t(kin)
        if Sk is not None and not is_zero(f):
            self.S = add_stress(self.S, scale(f, Sk))
        if not self.tangent:
            return
        if not is_zero(d2f) and not is_zero(g):  # g was formed above whenever f'' != 0
            self.g2 = add_optional(self.g2, d2f * g)
        if Sk is not None and not is_zero(df):
            self.S_hat = add_stress(self.S_hat, scale(df, Sk))
        for pair, coef in zip(term.g.tangent, term.g.tangent_coefficients(kin)):
            key = slot_key(pair)
            self.pair_weights[key] = add_optional(self.pair_weights.get(key), scale_weight(f, coef))


@dataclass(frozen=True)
class Aggregates:
    """All groups folded, each weighted by c (plain) or c phi'(u); None is zero.

    energy: (m,) W per cell (not multiplied by the rest volume), or None if not asked.
    S: S-bar, component-major (3, 3, m) or a (3, 3) constant. S_hat: S-hat, the same.
    h: (m,). g2: (m,).
    weights: tangent-pair weights by :func:`slot_key`, each (m,) or a float.
    rank_one: (c phi''(u) (m,), du (3, 4, m)) of each non-plain group.
    S_hat, g2, weights and rank_one are formed only when the stiffness is asked (else None,
    None, {} and ()).
    """

    energy: Optional[np.ndarray]
    S: Optional[np.ndarray]
    S_hat: Optional[np.ndarray]
    h: Optional[np.ndarray]
    g2: Optional[np.ndarray]
    weights: Mapping[Tuple[str, Hashable], object]
    rank_one: Tuple[Tuple[np.ndarray, np.ndarray], ...] = ()


def fold_groups(
    groups: Sequence[TermGroup],
    kin: Kinematics,
    J: np.ndarray,
    du_of: Optional[Callable[[object, object, int], np.ndarray]] = None,
    *,
    energy: bool = True,
) -> Aggregates:
    """Fold every group's sums into one :class:`Aggregates` record.

    Args:
        groups: the material's term groups.
        kin, J: the kinematics of every cell (m cells).
        du_of: given when the stiffness is asked: du_of(S, h, k) returns the gradient
            F S D_a + h d_a (3, 4, m) of the k-th non-plain group's u, for its rank-one
            term. Without it, only what the energy, the gradient and the stress need is
            formed (no S-hat, g2 or tangent coefficients: the force-only path).
        energy: also sum the energy (else Aggregates.energy is None and plain groups skip
            the values g of terms whose f is constant).
    """
    m = len(J)
    W = np.zeros(m) if energy else None
    S = S_hat = h = g2 = None
    weights: Dict[Tuple[str, Hashable], object] = {}
    rank_one = []
    for group in groups:
        sums = GroupSums(m, tangent=du_of is not None, value=energy or not group.plain)
        for term in group.terms:
            sums.add(term, kin, J)
        if not group.plain:
            phi, dphi, d2phi = group.function(sums.u)
            c = group.coefficient * dphi  # the weight of every sum that is linear in u's
            if energy:
                W += group.coefficient * phi
            if du_of is not None:
                rank_one.append((group.coefficient * d2phi, du_of(sums.S, sums.h, len(rank_one))))
        else:
            c = group.coefficient
            if energy:
                W += c * sums.u
        S = add_stress(S, scale_optional(c, sums.S))
        S_hat = add_stress(S_hat, scale_optional(c, sums.S_hat))
        h = add_optional(h, None if sums.h is None else c * sums.h)
        g2 = add_optional(g2, None if sums.g2 is None else c * sums.g2)
        for key, w in sums.pair_weights.items():
            weights[key] = add_optional(weights.get(key), scale_weight(c, w))
    return Aggregates(W, S, S_hat, h, g2, weights, tuple(rank_one))
