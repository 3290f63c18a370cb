"""Elastic constants converted to another pair and back, with one slip in a formula.

Many engines take Young's modulus and Poisson's ratio (an Abaqus UMAT's PROPS, a solver's input
file) while a kit gives Lame's constants or a bulk and a shear modulus, so a driver converts
them to (E, nu) and the routine converts back. With every formula right the round trip returns
the kit's values; with one formula written wrongly both moduli come back changed, and a fit of
the energy's terms sees "both parameters scaled by odd factors" (mu x 0.763, lam x -0.19).

Each candidate below is the round trip with exactly one formula wrong, from a declared list of
the slips engineers make (a factor 2 lost, 1 - nu for 1 - 2 nu, the plane-stress lambda). Its
prediction is two numbers, so a match to the fitted values at 1e-6 is evidence: no other
mechanism the diagnosis knows gives both.

The forward formulas, from (lam, mu) or from (K, mu):

    E = mu (3 lam + 2 mu) / (lam + mu),   nu = lam / (2 (lam + mu)),
    E = 9 K mu / (3 K + mu),              nu = (3 K - 2 mu) / (2 (3 K + mu));

the backward ones, to (lam, mu) or to (K, mu):

    mu = E / (2 (1 + nu)),   lam = E nu / ((1 + nu) (1 - 2 nu)),   K = E / (3 (1 - 2 nu)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Tuple

__all__ = ["Conversion", "conversion_slips", "matching_conversion", "moduli_names"]

#: Parameter names read as Lame's first parameter, the bulk modulus and the shear modulus.
_LAME = ("lam", "lmbda", "lambda_", "la")
_BULK = ("k0", "kappa", "K", "bulk")
_SHEAR = ("mu", "G")

Pair = Tuple[float, float]


@dataclass(frozen=True)
class Conversion:
    """One round trip with one slip: the values it gives each parameter, and its words."""

    values: Dict[str, float]
    words: str


# (E, nu) from the first modulus (lam or K) and mu: the right formulas and the slips.
def _young_lame(lam: float, mu: float) -> float:
    return mu * (3 * lam + 2 * mu) / (lam + mu)


def _poisson_lame(lam: float, mu: float) -> float:
    return lam / (2 * (lam + mu))


def _young_bulk(k: float, mu: float) -> float:
    return 9 * k * mu / (3 * k + mu)


def _poisson_bulk(k: float, mu: float) -> float:
    return (3 * k - 2 * mu) / (2 * (3 * k + mu))


_FORWARD: Dict[str, Tuple[Callable, Callable, Tuple[Tuple[str, Callable, Callable], ...]]] = {
    "lame": (
        _young_lame,
        _poisson_lame,
        (
            (
                "nu = lam / (lam + mu) where lam / (2 (lam + mu)) belongs (its 2 lost)",
                _young_lame,
                lambda lam, mu: lam / (lam + mu),
            ),
            (
                "E = mu (3 lam + 2 mu) / (2 (lam + mu)) (a 2 too many)",
                lambda lam, mu: mu * (3 * lam + 2 * mu) / (2 * (lam + mu)),
                _poisson_lame,
            ),
            (
                "E = 2 mu (1 + nu) computed with nu = lam / (lam + mu)",
                lambda lam, mu: 2 * mu * (1 + lam / (lam + mu)),
                lambda lam, mu: lam / (lam + mu),
            ),
        ),
    ),
    "bulk": (
        _young_bulk,
        _poisson_bulk,
        (
            (
                "nu = (3 K - 2 mu) / (3 K + mu) where (3 K - 2 mu) / (2 (3 K + mu)) belongs "
                "(its 2 lost)",
                _young_bulk,
                lambda k, mu: (3 * k - 2 * mu) / (3 * k + mu),
            ),
            (
                "E = 3 K mu / (3 K + mu) where 9 K mu / (3 K + mu) belongs",
                lambda k, mu: 3 * k * mu / (3 * k + mu),
                _poisson_bulk,
            ),
        ),
    ),
}


# (first modulus, mu) from (E, nu): the right formulas and the slips.
def _shear(e: float, nu: float) -> float:
    return e / (2 * (1 + nu))


def _lame(e: float, nu: float) -> float:
    return e * nu / ((1 + nu) * (1 - 2 * nu))


def _bulk(e: float, nu: float) -> float:
    return e / (3 * (1 - 2 * nu))


_BACKWARD: Dict[str, Tuple[Callable, Callable, Tuple[Tuple[str, Callable, Callable], ...]]] = {
    "lame": (
        _lame,
        _shear,
        (
            ("mu = E / (1 + nu) where E / (2 (1 + nu)) belongs", _lame, lambda e, nu: e / (1 + nu)),
            (
                "lam = E nu / ((1 + nu) (1 - nu)) = E nu / (1 - nu^2), the plane-stress "
                "lambda, where the 3D E nu / ((1 + nu) (1 - 2 nu)) belongs",
                lambda e, nu: e * nu / (1 - nu * nu),
                _shear,
            ),
            (
                "lam = E / ((1 + nu) (1 - 2 nu)) where E nu / ((1 + nu) (1 - 2 nu)) belongs "
                "(its nu lost)",
                lambda e, nu: e / ((1 + nu) * (1 - 2 * nu)),
                _shear,
            ),
        ),
    ),
    "bulk": (
        _bulk,
        _shear,
        (
            ("mu = E / (1 + nu) where E / (2 (1 + nu)) belongs", _bulk, lambda e, nu: e / (1 + nu)),
            (
                "K = E / (3 (1 - nu)) where E / (3 (1 - 2 nu)) belongs",
                lambda e, nu: e / (3 * (1 - nu)),
                _shear,
            ),
            (
                "K = E / (1 - 2 nu) where E / (3 (1 - 2 nu)) belongs (its 3 lost)",
                lambda e, nu: e / (1 - 2 * nu),
                _shear,
            ),
        ),
    ),
}


def _pairs(values: Dict[str, float]) -> List[Tuple[str, str, str]]:
    """(kind, first modulus' name, shear modulus' name) for each pair the parameters hold."""
    shear = [n for n in _SHEAR if n in values]
    if not shear:
        return []
    out = [("lame", n, shear[0]) for n in _LAME if n in values]
    out += [("bulk", n, shear[0]) for n in _BULK if n in values]
    return out


def conversion_slips(values: Dict[str, float]) -> List[Conversion]:
    """Every round trip through (E, nu) with one slip, for each (lam or K, mu) pair in
    ``values`` (the model's scalar parameters): the values it gives the two parameters.
    """
    out: List[Conversion] = []
    for kind, first, shear in _pairs(values):
        a, mu = float(values[first]), float(values[shear])
        young, poisson, forward_slips = _FORWARD[kind]
        back_first, back_shear, backward_slips = _BACKWARD[kind]
        trips = [
            (f"to (E, nu) with {w}, then back", fe, fn, back_first, back_shear)
            for w, fe, fn in forward_slips
        ]
        trips += [
            (f"to (E, nu) and back with {w}", young, poisson, bf, bs)
            for w, bf, bs in backward_slips
        ]
        for words, fe, fn, bf, bs in trips:
            try:
                e, nu = fe(a, mu), fn(a, mu)
                got = {first: bf(e, nu), shear: bs(e, nu)}
            except ZeroDivisionError:
                continue
            out.append(
                Conversion(
                    got,
                    f"{first} and {shear} converted {words}: {first} = {got[first]:.6g}, "
                    f"{shear} = {got[shear]:.6g} where the case has {a:g} and {mu:g}",
                )
            )
    return out


def matching_conversion(
    values: Dict[str, float], fitted: Dict[str, float], close: float = 1e-6
) -> List[Conversion]:
    """The round trips of :func:`conversion_slips` that change exactly the parameters of
    ``fitted`` (a parameter's value changed by more than ``close``, relative) and give them the
    fitted values (relative ``close``).
    """
    found = []
    for conv in conversion_slips(values):
        changed = {
            p: v
            for p, v in conv.values.items()
            if abs(v - values[p]) > close * max(abs(values[p]), 1e-300)
        }
        if not changed or set(changed) != set(fitted):
            continue
        if all(abs(changed[p] - fitted[p]) <= close * abs(fitted[p]) for p in fitted):
            found.append(conv)
    return found


def moduli_names(values: Dict[str, float]) -> set:
    """The names in ``values`` that a conversion of :func:`conversion_slips` can change."""
    return {name for _, first, shear in _pairs(values) for name in (first, shear)}
