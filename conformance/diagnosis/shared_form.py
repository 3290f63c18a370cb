"""One compiled form for every variant of an energy that differs from another only in numbers.

The diagnosis asks the oracle for many variants of one model's energy (:class:`Spec`): each
additive term alone (the term fit), every non-integer power of J scaled by a factor (the
isochoric power left out, halved or doubled; the exponents fitted), the density weighted by J
(the deformed volume). Written with those numbers in the UFL, each variant was a form of its
own, and on a machine with empty caches each cost FFCx's code generation and a C compile
(Costa: about 2.7 s a form, 16 forms). Here they are one expression with the numbers as
Constants,

    W_spec = (1 + d (J - 1)) ( sum_t w_t T_t + w_0 sum_k C_k ),   J^e -> J^(s_e e),

T_t the additive terms that depend on the deformation, C_k the others (a rest constant), w_t
the terms' weights (1 for the term evaluated, or all of them for the whole energy), w_0 = 1 for
the whole energy only, d = 1 for the deformed volume, s_e each power's factor; so every such
Spec of a model compiles to the same code and FFCx's cache serves all but the first. At weights
and factors 0 or 1 the values are those of the Spec's own form up to the order of additions.

The variants that change the kinematics themselves (F transposed, the strain measure, the
stretches, the frame deformed, a power of J moved out of an exponential) keep a form each.
"""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Tuple

from conformance.diagnosis.energy_terms import (
    Spec,
    _is_integer_literal,
    _refit_j_powers,
    additive_parts,
    exponent_key,
    written_energy,
)

__all__ = ["applies", "energy"]


def applies(spec: Spec) -> bool:
    """Whether ``spec`` differs from the model's own kinematics only in numbers (terms, factors of
    the powers of J, the deformed volume), so that it can share the model's one variant form.
    """
    return (
        not spec.transpose
        and spec.eigen_power == 1.0
        and spec.i1 is None
        and not spec.frame_deformed
        and spec.strain is None
        and not spec.j_out_of_exp
        # a term of J W is J W itself (the product is not split); left to its own form
        and not (spec.deformed_volume and spec.term is not None)
    )


def energy(model: Any, F, frame, constant: Callable[[Any], Any], spec: Spec):
    """``model``'s energy evaluated as ``spec`` says (:func:`applies` must hold), written so that
    every such spec gives the same UFL up to the values of its Constants (``constant`` makes
    one from a number, as the oracle's parameters are made).
    """
    import ufl

    if not applies(spec):
        raise ValueError(f"{spec} changes the kinematics: it has a form of its own")
    W, entered = written_energy(model, F, frame, constant, spec)
    W = _powers_of_j_with_factors(W, spec, entered, constant)
    terms, rest = additive_parts(W, F)
    if spec.term is not None and spec.term >= len(terms):
        raise ValueError(f"term {spec.term} of {len(terms)}")
    whole = spec.term is None
    total = sum(
        (constant(1.0 if whole or t == spec.term else 0.0) * T for t, T in enumerate(terms)),
        ufl.zero(),
    )
    if rest:
        total = total + constant(1.0 if whole else 0.0) * sum(rest[1:], rest[0])
    d = constant(1.0 if spec.deformed_volume else 0.0)
    return (1.0 + d * (ufl.det(F) - 1.0)) * total


def _factor(spec: Spec, key: str, printed: str) -> float:
    """The factor of one power of J: its fitted factor (``j_exponents``) times the scaling of
    every power, or of the one printed as ``j_power_of`` (``j_power``).
    """
    r = dict(spec.j_exponents).get(key, 1.0)
    if spec.j_power != 1.0 and (spec.j_power_of is None or printed == spec.j_power_of):
        r *= spec.j_power
    return r


def _powers_of_j_with_factors(W, spec: Spec, entered: List[Tuple[Any, str]], constant):
    """W with every non-integer power of J, J^e, written J^(s e), s a Constant (one per
    distinct exponent) holding its factor for ``spec``: energy_terms' refit of the powers of J
    with every exponent listed, so that every spec gives the same expression.
    """
    from ufl.classes import Determinant, Power
    from ufl.corealg.traversal import unique_pre_traversal

    factors: Dict[str, float] = {}
    for node in unique_pre_traversal(W):
        if isinstance(node, Power) and isinstance(node.ufl_operands[0], Determinant):
            exponent = node.ufl_operands[1]
            if not _is_integer_literal(exponent):
                key = exponent_key(exponent, entered)
                factors.setdefault(key, _factor(spec, key, str(exponent)))
    return _refit_j_powers(W, factors, entered, constant)
