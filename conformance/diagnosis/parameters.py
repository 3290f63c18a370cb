"""Parameters the engine read differently: two exchanged, or one with another value.

The term fit (:mod:`conformance.diagnosis.term_fit`) sees a parameter that multiplies its terms;
one that enters non-linearly (Costa's b_ij inside exp(Q), Veronda-Westmann's c2, Ogden's alpha)
it cannot. Here the oracle is evaluated with the parameters themselves changed:

- every pair of parameters of the same unit exchanged (the units as the material's declaration
  writes them, "`a`, `k0` (Pa); `b_ff`, ... (dimensionless)"; a user energy's parameters have
  no declared unit, so every pair of them);
- each parameter alone refitted (:func:`conformance.diagnosis.refit.refit`): the value with
  which the oracle matches the engine, named with the parameter it equals when it is another's;
- the whole parameter list read by position in another order (:func:`reorderings`: the kit
  lists the parameters in the declaration's order, an engine's constructor or table may take
  them in its own), units regardless: every order of a model's parameters (at most
  :data:`MAX_REORDERED` of them) that the exchanges above do not already try.

Each hypothesis is a model the oracle evaluates like the case's own; it is named only when the
engine agrees with it within the case's tolerance, and the caller shows two that agree and
predict differently as ambiguous.
"""

from __future__ import annotations

import dataclasses
import itertools
import re
from dataclasses import dataclass
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from conformance.diagnosis.elastic_conversions import matching_conversion

__all__ = [
    "Exchange",
    "MAX_REORDERED",
    "Reordering",
    "reorderings",
    "convention_words",
    "elastic_convention_words",
    "declared_units",
    "exchanges",
    "permutation_words",
    "scalar_parameters",
    "unit_groups",
    "with_value",
]


def _is_user_energy(model: Any) -> bool:
    from reference_fem.user_energy import UserEnergy

    return isinstance(model, UserEnergy)


def scalar_parameters(model: Any) -> Dict[str, float]:
    """The model's finite scalar parameters, by name, in their declared order."""
    if _is_user_energy(model):
        return {k: float(v) for k, v in model.params.items()}
    out: Dict[str, float] = {}
    if not dataclasses.is_dataclass(model):
        return out
    for fl in dataclasses.fields(model):
        v = getattr(model, fl.name)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v):
            out[fl.name] = float(v)
    return out


def declared_units(model: Any) -> Dict[str, Optional[str]]:
    """Each parameter's unit as the declaration's ``parameters`` text writes it (names in
    backticks, then their unit in parentheses: "`mu`, `k0` (Pa), `alpha` (dimensionless)");
    None for every parameter of a model without a declaration.
    """
    names = scalar_parameters(model)
    units: Dict[str, Optional[str]] = dict.fromkeys(names)
    if _is_user_energy(model):
        return units
    from mjed.materials.declaration import declaration_of

    try:
        text = declaration_of(type(model)).parameters or ""
    except LookupError:
        return units
    pending: List[str] = []
    for m in re.finditer(r"`([^`]+)`|\(([^()]*)\)", text):
        if m.group(1) is not None:
            pending.append(m.group(1))
        else:
            unit = m.group(2).split(",")[0].strip()
            for n in pending:
                if n in units:
                    units[n] = unit
            pending = []
    return units


def with_value(model: Any, **values: float) -> Any:
    """``model`` with some parameters replaced (the model's own validation applies: ValueError)."""
    import warnings

    with warnings.catch_warnings():  # a changed parameter may pre-stress: that is the point
        warnings.simplefilter("ignore")
        if _is_user_energy(model):
            return dataclasses.replace(model, params={**model.params, **values})
        return dataclasses.replace(model, **values)


def scaled_models(model: Any, factors: Sequence[float]) -> Iterator[Tuple[str, List[Any]]]:
    """(name, [model with that parameter times each factor]) for every non-zero scalar parameter
    of ``model`` whose scaled values the model accepts (its validation refuses none): the models
    from which a parameter's part of the energy is read off.
    """
    for name, v in scalar_parameters(model).items():
        if v == 0.0:
            continue
        try:
            yield name, [with_value(model, **{name: v * k}) for k in factors]
        except (TypeError, ValueError):
            continue


@dataclass(frozen=True)
class Exchange:
    """Two parameters exchanged: names p, q (the declared values vp, vq), and the model that
    reads vq for p and vp for q.
    """

    p: str
    q: str
    vp: float
    vq: float
    model: Any

    def title(self) -> str:
        return f"parameters {self.p} and {self.q} exchanged"

    def words(self) -> str:
        return (
            f"{self.p} = {self.vq:g} and {self.q} = {self.vp:g} in the engine where the case "
            f"has {self.p} = {self.vp:g}, {self.q} = {self.vq:g}: "
        )


def exchanges(model: Any) -> List[Exchange]:
    """Every exchange of two parameters of the same declared unit (every pair where units are
    not declared) that changes the model and that the model accepts.
    """
    values = scalar_parameters(model)
    units = declared_units(model)
    out = []
    for p, q in itertools.combinations(values, 2):
        if units[p] is not None and units[p] != units[q]:
            continue
        vp, vq = values[p], values[q]
        if vp == vq:
            continue
        try:
            swapped = with_value(model, **{p: vq, q: vp})
        except (ValueError, TypeError):
            continue
        out.append(Exchange(p, q, vp, vq, swapped))
    return out


#: Models with more scalar parameters than this are not reordered (24 orders of four).
MAX_REORDERED = 4


@dataclass(frozen=True)
class Reordering:
    """The case's parameter list read in another order: names (the declared order, which the
    kit lists), values (the case's), order (the engine's parameter names[i] holds the case's
    value of names[order[i]]) and the model so read.
    """

    names: Tuple[str, ...]
    values: Tuple[float, ...]
    order: Tuple[int, ...]
    model: Any

    def moved(self) -> List[int]:
        return [i for i, j in enumerate(self.order) if i != j]

    def title(self) -> str:
        said = " and ".join(
            f"{self.names[i]} = {self.values[self.order[i]]:g} (the case's "
            f"{self.names[self.order[i]]})"
            for i in self.moved()
        )
        both = len(self.moved()) == 2
        return (
            f"parameters read by position in another order: {said} in your engine; the case "
            f"lists ({', '.join(self.names)}) and your engine took that list in the order "
            f"({', '.join(self.names[j] for j in self.order)})"
            + (" (two parameters exchanged)" if both else " (parameters permuted)")
        )

    def words(self) -> str:
        return (
            "the oracle with "
            + ", ".join(f"{self.names[i]} = {self.values[self.order[i]]:g}" for i in self.moved())
            + ": "
        )


def reorderings(model: Any) -> List[Reordering]:
    """Every order of the model's scalar parameters (at most :data:`MAX_REORDERED` of them)
    that changes the model, that the model accepts and that :func:`exchanges` does not try
    (an exchange of two of one declared unit, or of two undeclared ones).
    """
    values = scalar_parameters(model)
    if len(values) > MAX_REORDERED:
        return []
    names = tuple(values)
    vals = tuple(values[n] for n in names)
    units = declared_units(model)
    out = []
    for order in itertools.permutations(range(len(names))):
        moved = [i for i, j in enumerate(order) if vals[i] != vals[j]]
        if not moved:
            continue
        if len(moved) == 2 and units[names[moved[0]]] == units[names[moved[1]]]:
            continue  # an exchange within one unit (or two undeclared): exchanges()'s
        try:
            model_o = with_value(model, **{names[i]: vals[order[i]] for i in moved})
        except (ValueError, TypeError):
            continue
        out.append(Reordering(names, vals, order, model_o))
    return out


#: (material class name, parameter) -> what the squared value means: the parameter given in a
#: convention where its square root is entered (Arruda-Boyce's chain parameter N = lambda_m^2).
_SQUARED = {
    ("ArrudaBoyce", "N"): "N used as lambda_m^2: the locking stretch lambda_m given where N "
    "(= lambda_m^2) is expected, and squared",
}

#: (material class name, parameter) -> (shift, words): the value used is the declared one plus
#: shift, the parameter read in a convention offset by it (Gent's Jm, the limit of I1b - 3,
#: taken as the limit of I1b).
_SHIFTED = {
    ("Gent", "Jm"): (
        (-3.0, "Jm taken as the limiting value of I1b, so Jm - 3 used as the limit of I1b - 3"),
        (3.0, "Jm + 3 used: the limit of I1b given where that of I1b - 3 is expected"),
    ),
}


#: Parameter names read as Lame's first parameter, and as the bulk modulus.
_LAME = ("lam", "lmbda", "lambda_", "la")
_BULK = ("k0", "kappa", "K", "bulk")


def _shear_moduli(values: Dict[str, float]) -> Dict[str, float]:
    """The small-strain shear modulus in the model's parameters, by how it is written: mu, or
    2 c10 (Yeoh), 2 (c1 + c2) (Mooney-Rivlin); empty when none is there.
    """
    out: Dict[str, float] = {}
    if "mu" in values:
        out["mu"] = values["mu"]
    if "c10" in values:
        out["2 c10"] = 2.0 * values["c10"]
    if "c1" in values and "c2" in values and "mu" not in values:
        out["2 (c1 + c2)"] = 2.0 * (values["c1"] + values["c2"])
    return out


def elastic_convention_words(model: Any, name: str, value: float, declared: float) -> str:
    """Words for a refitted ``value`` of Lame's lambda or of the bulk modulus that is the
    ``declared`` one converted between the two, K = lambda + 2 mu/3 (mu the model's shear
    modulus, :func:`_shear_moduli`): lambda used as K in a bulk/shear split (its effective value
    lambda - 2 mu/3), K entered where lambda belongs (lambda + 2 mu/3), and the converse for a
    bulk modulus; "" otherwise.
    """
    values = scalar_parameters(model)
    for mu_name, mu in _shear_moduli(values).items():
        if mu == 0 or mu_name == name:
            continue
        two = f"2 {mu_name}/3" if " " not in mu_name else f"2/3 x {mu_name}"
        if name in _LAME:
            cases = (
                (
                    -1.0,
                    f"{name} used as the bulk modulus kappa in a bulk/shear split, so the "
                    f"effective Lame parameter is {name} - {two} (the convention K = lam + "
                    "2 mu/3 confused)",
                ),
                (
                    1.0,
                    f"the bulk modulus K = {name} + {two} entered where Lame's lambda belongs "
                    "(the convention K = lam + 2 mu/3 confused)",
                ),
            )
        elif name in _BULK:
            cases = (
                (
                    1.0,
                    f"{name} taken as Lame's lambda and converted to the bulk modulus "
                    f"{name} + {two} (the convention K = lam + 2 mu/3 confused)",
                ),
                (
                    -1.0,
                    f"{name} converted to Lame's lambda = {name} - {two} and used as the bulk "
                    "modulus (the convention K = lam + 2 mu/3 confused)",
                ),
            )
        else:
            return ""
        for sign, words in cases:
            if abs(value - (declared + sign * 2.0 * mu / 3.0)) <= 1e-6 * max(abs(declared), 1.0):
                return f" ({words})"
    return ""


def convention_words(model: Any, name: str, value: float, declared: float) -> str:
    """Words for a refitted parameter ``value`` that is the ``declared`` value in another
    convention: squared or its square root (any parameter), or shifted as :data:`_SHIFTED`
    lists for its material; "" otherwise.
    """
    elastic = elastic_convention_words(model, name, value, declared)
    if elastic:
        return elastic
    converted = matching_conversion(scalar_parameters(model), {name: value})
    if converted:
        return f" ({converted[0].words})"
    for shift, words in _SHIFTED.get((type(model).__name__, name), ()):
        if abs(value - (declared + shift)) <= 1e-6 * max(abs(declared), 1.0):
            return f" ({name} {'-' if shift < 0 else '+'} {abs(shift):g}: {words})"
    if declared <= 0 or value <= 0 or abs(declared - 1.0) < 1e-3:
        return ""  # 1 squared is 1: no convention can be told
    if name in _BULK and abs(value - 2.0 * declared) <= 2e-6 * declared:
        return (
            f" (twice {name}: a compressibility D1 = 1/K given to a routine that reads "
            "K = 2/D1 (Abaqus' convention), or the volumetric energy doubled)"
        )
    if name in _BULK and abs(value - 0.5 * declared) <= 1e-6 * declared:
        return (
            f" (half {name}: a compressibility D1 = 2/K (Abaqus' convention) read as K = 1/D1, "
            "or the volumetric energy halved)"
        )
    if name in _BULK and abs(value * declared - 2.0) <= 2e-6:
        return (
            f" (2/{name}: {name} used as Abaqus' compressibility D1 = 2/K, or a D1 converted as "
            "if it were K)"
        )
    if abs(value * declared - 1.0) <= 1e-6:
        return f" (1/{name}: the parameter entered as its inverse, a compliance for a modulus)"
    if abs(value - declared**2) <= 1e-6 * declared**2:
        known = _SQUARED.get((type(model).__name__, name))
        return (
            f" ({name} squared, {declared:g}^2: {known})"
            if known
            else f" ({name} squared, {declared:g}^2: the parameter entered in another convention)"
        )
    if abs(value - np.sqrt(declared)) <= 1e-6 * np.sqrt(declared):
        return (
            f" (the square root of {name} = {declared:g}: the parameter entered in another "
            "convention)"
        )
    for k in (1, 2, 3):
        for factor, how in ((1000.0**-k, "divided"), (1000.0**k, "multiplied")):
            if abs(value - factor * declared) <= 1e-6 * factor * declared:
                unit = declared_units(model).get(name)
                kind = f"its unit {unit}" if unit else "a dimensionless parameter"
                return (
                    f" ({name} {how} by {1000**k:g}: a unit conversion applied to {name} "
                    f"({kind}) where it does not belong, or one missing, e.g. Pa and kPa)"
                )
    return ""


def unit_groups(model: Any) -> List[List[str]]:
    """The model's scalar parameters grouped by declared unit, groups of three or more (two are
    :func:`exchanges`'s); none for a model without declared units.
    """
    groups: Dict[str, List[str]] = {}
    for name, unit in declared_units(model).items():
        if unit is not None:
            groups.setdefault(unit, []).append(name)
    return [g for g in groups.values() if len(g) >= 3]


def permutation_words(
    names: Sequence[str], fitted: Sequence[float], declared: Sequence[float], rel: float = 1e-6
) -> Optional[str]:
    """Words for refitted values of the parameters ``names`` that are their declared values in
    another order, three or more moved (two moved is an exchange); None otherwise (the values
    are not the declared ones rearranged, or nothing moved).
    """
    v, d = np.asarray(fitted, dtype=float), np.asarray(declared, dtype=float)
    scale = np.maximum(np.abs(d), 1e-300)
    if not np.allclose(np.sort(v), np.sort(d), rtol=rel, atol=0.0):
        return None
    moved = [i for i in range(len(names)) if abs(v[i] - d[i]) > rel * scale[i]]
    if len(moved) < 3:
        return None
    said = []
    for i in moved:
        sources = [names[j] for j in range(len(names)) if abs(v[i] - d[j]) <= rel * scale[j]]
        said.append(f"{names[i]} = {v[i]:.6g} (the case's {' or '.join(sources)})")
    return (
        f"parameters {', '.join(names[i] for i in moved)} read in another order (a list taken "
        f"by position in another convention's order): {'; '.join(said)}"
    )
