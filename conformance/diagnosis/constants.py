"""A constant of the formula with another value: the exponents of J.

The numbers written into an energy's formula are as much a part of it as its parameters, and
engines get them wrong: the isochoric exponents -2/3 and -4/3 typed as rounded decimals
(-0.66667), Ogden's J^(-alpha/3) written J^(-2/3), one isochoric factor forgotten or squared.
Each non-integer power of J in the declared formula (or the user's) is refitted: the oracle
evaluates the energy with J^(r_k p_k) for each exponent p_k
(:class:`conformance.diagnosis.energy_terms.Spec`, ``j_exponents``), and the factors r_k are
fitted together (:func:`conformance.diagnosis.refit.refit`) to the engine's force and
stiffness. When the engine then agrees with the oracle within the case's tolerance, the
exponents whose factor is not 1 are named, with the value the engine uses.

The other constants need no fit of their own: a factor (the 1/2 of k/2 (ln J)^2, the 1/2 of
c1 c2 / 2) scales its term, which the term fit (:mod:`conformance.diagnosis.term_fit`) names; an
additive constant (the 3 of I1b - 3) changes only the energy, which the force-right reading
reports; a constant inside a function (exp(c2 (I1b - 3))) changes that term by a factor too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Tuple

import numpy as np

from conformance.diagnosis.fractions import written_number
from conformance.diagnosis.refit import Refit, Target, refit

__all__ = ["ExponentFit", "fit_exponents", "describe_exponent", "written_exponent"]

#: A fitted factor within this of 1 (relative) leaves its exponent as declared.
_SAME = 1e-9


@dataclass(frozen=True)
class ExponentFit:
    """exponents: [(key, declared value)]; fit: the factors fitted (one per exponent)."""

    exponents: Tuple[Tuple[str, float], ...]
    fit: Refit

    def changed(self) -> List[Tuple[str, float, float]]:
        """[(key, declared exponent, the engine's exponent)] of the exponents not at 1."""
        return [
            (k, p, r * p)
            for (k, p), r in zip(self.exponents, self.fit.values)
            if abs(r - 1.0) > _SAME
        ]


def _fraction(x: float) -> str:
    """A number as a short fraction when it is one (-2/3), else as a decimal (-0.66667)."""
    return written_number(x, rtol=1e-12, digits=6)


def written_exponent(key: str) -> str:
    """An exponent's key as a formula would write it: "-1 * alpha / 3.0" -> "-alpha/3"."""
    try:
        return _fraction(float(key))
    except ValueError:
        return key.replace("-1 * ", "-").replace(".0", "").replace(" / ", "/")


def describe_exponent(key: str, declared: float, engine: float) -> str:
    """The exponent in words: "J^(-2/3) of the formula is J^(-0.66667) in your engine"."""
    written = written_exponent(key)
    value = "" if written == _fraction(declared) else f" = J^({_fraction(declared)})"
    return f"J^({written}){value} of the formula is J^({_fraction(engine)}) in your engine"


def fit_exponents(
    exponents: List[Tuple[str, float]],
    evaluate: Callable[[Tuple[Tuple[str, float], ...]], Tuple[np.ndarray, Any]],
    target: Target,
) -> Optional[ExponentFit]:
    """The factors of the exponents of J that best match the engine's ``target`` (``evaluate(((key,
    factor), ...)) -> (f, K)`` the oracle with them); None when no factor explains the error (see
    :func:`conformance.diagnosis.refit.refit`).
    """
    if not exponents:
        return None
    keys = [k for k, _ in exponents]
    fit = refit(
        lambda r: evaluate(tuple(zip(keys, (float(v) for v in r)))),
        [1.0] * len(keys),
        target,
    )
    return None if fit is None else ExponentFit(tuple(exponents), fit)
