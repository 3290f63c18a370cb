"""A material's power groups written out term by term, as an engine that expands them does.

MJED keeps Yeoh's ``c20 (I1b - 3)^2`` as one group, ``c power(u)`` of the inner sum
``u = J^(-2/3) I1``, with its own chain-rule blocks (the outer ``phi''(u) du (x) du``). An engine
may instead expand the power by the binomial theorem into plain MJED terms,

    c (s + a J^q I1)^p = sum_j c C(p, j) s^(p-j) a^j J^(q j) I1^j,

each ``f(J) g(C)`` with ``f = J^(q j)`` and ``g = I1^j``, whose sum is the same energy but whose
parts (the J-J, cross and material blocks of each term) are not the group's. A mistake in one
of those parts is then a mistake in the expanded terms' parts, which the group's parts cannot
express. :func:`expanded_model` gives the stand-in material with every such group expanded, for
:mod:`conformance.diagnosis.mjed_parts` to read the engine's parts on (its parts add up to the
oracle like the material's own).
"""

from __future__ import annotations

from math import comb
from typing import Any, Optional, Tuple

from mjed.materials.base import Material

__all__ = ["ExpandedMaterial", "expanded_groups", "expanded_model"]

#: The highest power expanded (Arruda-Boyce's series reaches I1b^5; beyond, nobody expands).
MAX_POWER = 5


class ExpandedMaterial(Material):
    """A stand-in material: ``groups``, the model's groups with its power groups expanded (an
    mjed material, so that mjed's force field evaluates it like any other).
    """

    def __init__(self, groups: Tuple[Any, ...]):
        self.groups = groups

    def decomposition(self) -> Tuple[Any, ...]:
        return self.groups


def _expandable(group: Any) -> bool:
    """A group c (s + a J^q I1)^p with p a whole number from 2 to :data:`MAX_POWER`."""
    from mjed.terms import I1Power, JPower, Power

    f = group.function
    if not isinstance(f, Power) or len(group.terms) != 1:
        return False
    p = f.p
    term = group.terms[0]
    return (
        float(p).is_integer()
        and 2 <= p <= MAX_POWER
        and isinstance(term.f, JPower)
        and isinstance(term.g, I1Power)
        and term.g.n == 1
    )


def expanded_groups(groups: Tuple[Any, ...]) -> Optional[Tuple[Any, ...]]:
    """``groups`` with every expandable power group written out as one plain group of its
    binomial terms (the constant term dropped: it moves nothing); None when none expands.
    """
    from mjed.terms import I1Power, JPower, Term, TermGroup

    out, changed = [], False
    for group in groups:
        if not _expandable(group):
            out.append(group)
            continue
        changed = True
        term, p, s = group.terms[0], int(group.function.p), group.function.shift
        q, a = term.f.p, term.g.c
        terms = tuple(
            Term(JPower(q * j), I1Power(group.coefficient * comb(p, j) * s ** (p - j) * a**j, j))
            for j in range(1, p + 1)
        )
        out.append(TermGroup(terms))
    return tuple(out) if changed else None


def expanded_model(model: Any) -> Optional[ExpandedMaterial]:
    """The stand-in for ``model`` with its power groups expanded, or None (no MJED
    decomposition, or nothing to expand).
    """
    decomposition = getattr(model, "decomposition", None)
    if decomposition is None:
        return None
    groups = expanded_groups(tuple(decomposition()))
    return None if groups is None else ExpandedMaterial(groups)
