"""Term aggregation: a material's term groups folded into the sums the engine needs.

For one group with u = sum_k f_k g_k (paper, eqs. 3-4):

    S-bar = sum_k f_k S_k,  S-hat = sum_k f'_k S_k,  h = sum_k f'_k g_k,  g2 = sum_k f''_k g_k,

and, per declared tangent pair, the weight sum_k f_k beta_k (or gamma_k). A plain group
contributes c u, an exponential group c e^u. Everything in the Hessian but the rank-one term
c e^u du (x) du of an exponential group is linear in these sums, so all groups are folded
into one :class:`Aggregates` record (each weighted by c or c e^u) before any 3x3 algebra.
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

__all__ = ["slot_key", "GroupSums", "Aggregates", "fold_groups"]

def slot_key(pair: TangentPair) -> Tuple[str, Hashable]:
    """The key shared by all tangent pairs with the same kind and the same constant matrix
    (per-cell matrices are keyed by identity)."""
    if pair.kind == "spectral":
        return pair.kind, None
    m = pair.matrix
    if m.ndim == 2:
        return pair.kind, m.tobytes()
    return pair.kind, id(m)


def add_optional(acc, value):
    """acc + value where None stands for zero (so absent terms cost nothing)."""
    if value is None:
        return acc
    return value if acc is None else acc + value


def scale(s, A):
    """s * A with s per cell, (m,) or scalar, and A (m, ...) or scalar."""
    if np.ndim(s) == 0 or np.ndim(A) <= 1:
        return s * A
    return np.reshape(s, np.shape(s) + (1,) * (np.ndim(A) - 1)) * A


def scale_optional(s, A):
    return None if A is None else scale(s, A)


class GroupSums:
    """Running sums of one group's terms: u, S-bar, S-hat, h, g2 and the tangent weights."""

    def __init__(self, m: int):
        self.m = m
        self.u = np.zeros(m)
        self.S = None
        self.S_hat = None
        self.h = None
        self.g2 = None
        self.pair_weights: Dict[Tuple[str, Hashable], object] = {}

    def add(self, term: Term, kin: Kinematics, J: np.ndarray) -> None:
        f, df, d2f = term.f(J)
        g = term.g.value(kin)
        self.u += f * g
        if not is_zero(df) and not is_zero(g):
            self.h = add_optional(self.h, df * g)
        if not is_zero(d2f) and not is_zero(g):
            self.g2 = add_optional(self.g2, d2f * g)
        Sk = term.g.stress(kin)
        if Sk is not None:
            if not is_zero(f):
                self.S = add_optional(self.S, scale(f, Sk))
            if not is_zero(df):
                self.S_hat = add_optional(self.S_hat, scale(df, Sk))
        for pair, coef in zip(term.g.tangent, term.g.tangent_coefficients(kin)):
            key = slot_key(pair)
            self.pair_weights[key] = add_optional(self.pair_weights.get(key), scale(f, coef))


@dataclass(frozen=True)
class Aggregates:
    """All groups folded, each weighted by c (plain) or c e^u (exponential); None is zero.

    energy: (m,) W per cell (not multiplied by the rest volume).
    S: S-bar (m, 3, 3) or (3, 3). S_hat: S-hat. h: (m,). g2: (m,).
    weights: tangent-pair weights by :func:`slot_key`, each (m,) or a float.
    rank_one: (c e^u (m,), du (3, 4, m)) of each exponential group, when the stiffness is asked.
    """

    energy: np.ndarray
    S: Optional[np.ndarray]
    S_hat: Optional[np.ndarray]
    h: Optional[np.ndarray]
    g2: Optional[np.ndarray]
    weights: Mapping[Tuple[str, Hashable], object]
    rank_one: Tuple[Tuple[np.ndarray, np.ndarray], ...] = ()


def fold_groups(groups: Sequence[TermGroup], kin: Kinematics, J: np.ndarray,
                du_of: Optional[Callable[[object, object, int], np.ndarray]] = None) -> Aggregates:
    """Fold every group's sums into one :class:`Aggregates` record.

    Args:
        groups: the material's term groups.
        kin, J: the kinematics of every cell (m cells).
        du_of: when given (the stiffness is asked), du_of(S, h, k) returns the gradient
            F S D_a + h d_a (3, 4, m) of the k-th exponential group's u, for its rank-one term.
    """
    m = len(J)
    energy = np.zeros(m)
    S = S_hat = h = g2 = None
    weights: Dict[Tuple[str, Hashable], object] = {}
    rank_one = []
    for group in groups:
        sums = GroupSums(m)
        for term in group.terms:
            sums.add(term, kin, J)
        if group.exponential:
            c = group.coefficient * np.exp(sums.u)
            energy += c
            if du_of is not None:
                rank_one.append((c, du_of(sums.S, sums.h, len(rank_one))))
        else:
            c = group.coefficient
            energy += c * sums.u
        S = add_optional(S, scale_optional(c, sums.S))
        S_hat = add_optional(S_hat, scale_optional(c, sums.S_hat))
        h = add_optional(h, None if sums.h is None else c * sums.h)
        g2 = add_optional(g2, None if sums.g2 is None else c * sums.g2)
        for key, w in sums.pair_weights.items():
            weights[key] = add_optional(weights.get(key), scale(c, w))
    return Aggregates(energy, S, S_hat, h, g2, weights, tuple(rank_one))
