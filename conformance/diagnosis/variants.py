"""Which energy does the engine compute? Variant energies evaluated through the oracle.

When no correction explains a failure, the case's energy is written as a formula (the
material's declared energy, or the user's own) and rewritten the way engines
get it wrong: an invariant without its isochoric factor, the wrong power of J in it, I2 taken
as tr(C^2) or with tr(C^2) written from part of C (its diagonal, its Voigt entries once), the bulk
term k/2 (J-1)^2 or k/4 (J^2 - 1 - 2 ln J) for k/2 (ln J)^2, log10 J for ln J. Each variant
is a user energy (:class:`reference_fem.user_energy.UserEnergy`), so the oracle differentiates
it exactly as it does the built-in energies; a variant whose force and stiffness agree with the
engine's within the case's tolerances is named: "your engine matches W' = ...".

The rewrites are generic (they act on the invariants of any formula), not one per mutation:
adding a family is one line of :data:`REWRITES`.
"""

from __future__ import annotations

import functools
import re
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from mjed import materials as M

__all__ = ["REWRITES", "Variant", "energy_expression", "variants", "match_variant"]

Expression = Tuple[str, Dict[str, float]]


@functools.singledispatch
def energy_expression(model: Any) -> Optional[Expression]:
    """(formula in the user-energy syntax, parameters) of a model; None when the energy cannot
    be written in that syntax (Ogden's eigenvalues, Costa's frame).

    A declared material is written from its declaration's energy (:func:`_declared_expression`),
    the one the oracle differentiates; only St Venant-Kirchhoff, whose declared energy reads the
    matrix E, has its formula written out here in E's components.
    """
    return _declared_expression(model)


class _NotScalar(Exception):
    """The declared energy uses a matrix, the frame or eigenvalues: no scalar formula."""


def _operand(text: str) -> str:
    """``text`` as it can stand after ``/`` or around ``**``: as it is when it is one name, one
    number, one call or one parenthesised group; else in parentheses (a/(2*b), not a/2*b).
    """
    if re.fullmatch(r"[A-Za-z_]\w*|\d+(\.\d*)?([eE][+-]?\d+)?", text):
        return text
    start = re.match(r"[A-Za-z_]\w*\(|\(", text)
    if start:
        depth = 0
        for i, ch in enumerate(text):
            depth += {"(": 1, ")": -1}.get(ch, 0)
            if depth == 0 and i >= start.end() - 1:
                if i == len(text) - 1:
                    return text  # the group opened first closes last
                break
    return f"({text})"


class _Sym:
    """A formula in the user-energy syntax, built by running a declared energy on it."""

    def __init__(self, text: str):
        self.text = text

    @staticmethod
    def of(x: Any) -> "_Sym":
        if isinstance(x, _Sym):
            return x
        if isinstance(x, (int, float)) and np.isfinite(x):
            text = str(int(x)) if x == int(x) and abs(x) < 1e15 else repr(float(x))
            return _Sym(text if x >= 0 else f"({text})")
        raise _NotScalar(type(x).__name__)

    def __add__(self, o):
        return _Sym(f"({self.text} + {_Sym.of(o).text})")

    def __radd__(self, o):
        return _Sym(f"({_Sym.of(o).text} + {self.text})")

    def __sub__(self, o):
        return _Sym(f"({self.text} - {_Sym.of(o).text})")

    def __rsub__(self, o):
        return _Sym(f"({_Sym.of(o).text} - {self.text})")

    def __mul__(self, o):
        return _Sym(f"{self.text}/2") if o == 0.5 else _Sym(f"{self.text}*{_Sym.of(o).text}")

    def __rmul__(self, o):
        return _Sym(f"{self.text}/2") if o == 0.5 else _Sym(f"{_Sym.of(o).text}*{self.text}")

    def __truediv__(self, o):
        return _Sym(f"({self.text}/{_operand(_Sym.of(o).text)})")

    def __rtruediv__(self, o):
        return _Sym(f"({_Sym.of(o).text}/{_operand(self.text)})")

    def __pow__(self, o):
        return _Sym(f"{_operand(self.text)}**{_operand(_Sym.of(o).text)}")

    def __neg__(self):
        return _Sym(f"(-{self.text})")

    def __eq__(self, o):  # a formula is never compared with a number (0.5 above)
        return False

    __hash__ = None  # type: ignore[assignment]


class _ScalarNamespace:
    """The invariants as symbols; C, E, the frame and eigenvalues have no scalar formula."""

    I1, I2, J, I1b, I2b = (_Sym(n) for n in ("I1", "I2", "J", "I1b", "I2b"))
    lnJ = _Sym("ln(J)")

    def exp(self, x: Any) -> _Sym:
        return _Sym(f"exp({_Sym.of(x).text})")

    def ln(self, x: Any) -> _Sym:
        return _Sym(f"ln({_Sym.of(x).text})")

    def __getattr__(self, name: str) -> Any:
        raise _NotScalar(name)


def _declared_expression(model: Any) -> Optional[Expression]:
    """The declared energy of ``model``'s type written as a formula of its scalar invariants and
    parameters (those it reads); None when it is not declared or not scalar.
    """
    import dataclasses

    from mjed.materials.declaration import declaration_of

    if not dataclasses.is_dataclass(model):
        return None
    try:
        declared = declaration_of(type(model))
    except LookupError:
        return None
    values = {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    used: Dict[str, float] = {}

    def p(name: str) -> _Sym:
        value = values[name]
        if not isinstance(value, (int, float)) or not np.isfinite(value):
            raise _NotScalar(name)
        used[name] = float(value)
        return _Sym(name)

    p.value = lambda name: float(values[name])  # type: ignore[attr-defined]
    try:
        W = declared.energy(p, _ScalarNamespace())
    except (_NotScalar, KeyError, TypeError, ValueError):
        return None
    return (W.text, used) if isinstance(W, _Sym) else None


@energy_expression.register
def _(m: M.StVenantKirchhoff) -> Expression:
    trE2 = "(E11**2 + E22**2 + E33**2 + 2*(E12**2 + E13**2 + E23**2))"
    return f"lam/2*(E11 + E22 + E33)**2 + mu*{trE2}", {"mu": m.mu, "lam": m.lam}


def _user(m) -> Optional[Expression]:
    """A user energy's own formula (one with a fibre is left out: variants keep no fibre)."""
    return None if m.fibre is not None else (m.expression, dict(m.params))


@dataclass(frozen=True)
class Rewrite:
    """code; words: the mistake; pattern: a regular expression on the formula; replacement."""

    code: str
    words: str
    pattern: str
    replacement: str


#: I2 = (I1^2 - tr(C^2)) / 2 with tr(C^2) = sum_ij C_ij^2 written from part of C: its diagonal
#: only, or its six Voigt entries each once (the off-diagonal ones belong twice).
_I2_DIAGONAL = "((I1**2 - (C11**2 + C22**2 + C33**2))/2)"
_I2_VOIGT = "((I1**2 - (C11**2 + C22**2 + C33**2 + C12**2 + C13**2 + C23**2))/2)"

#: The mistake families, each a rewrite of the formula's invariants or of its bulk term.
REWRITES: Tuple[Rewrite, ...] = (
    Rewrite(
        "no-isochoric-I1", "I1 used where the isochoric I1b = J^(-2/3) I1 belongs", r"\bI1b\b", "I1"
    ),
    Rewrite(
        "no-isochoric-I2", "I2 used where the isochoric I2b = J^(-4/3) I2 belongs", r"\bI2b\b", "I2"
    ),
    Rewrite(
        "power-I1",
        "J^(-1/3) I1 used for I1b = J^(-2/3) I1 (the power of J halved)",
        r"\bI1b\b",
        "(J**(-1/3)*I1)",
    ),
    Rewrite(
        "power-I2",
        "J^(-2/3) I2 used for I2b = J^(-4/3) I2 (the power of J halved)",
        r"\bI2b\b",
        "(J**(-2/3)*I2)",
    ),
    Rewrite(
        "power-trC2-in-I2b",
        "I2b formed as (I1b^2 - J^(-2/3) tr(C^2)) / 2: the power of J of I1b reused on tr(C^2), "
        "where tr(C_bar^2) = J^(-4/3) tr(C^2) belongs",
        r"\bI2b\b",
        "((I1b**2 - J**(-2/3)*(I1**2 - 2*I2))/2)",
    ),
    Rewrite(
        "I2-as-trC2", "tr(C^2) used for I2 = (I1^2 - tr(C^2)) / 2", r"\bI2\b", "(I1**2 - 2*I2)"
    ),
    Rewrite(
        "I2-plus",
        "I2 = (I1^2 + tr(C^2)) / 2, the minus of (I1^2 - tr(C^2)) / 2 lost (I1b^2 - I2b for I2b)",
        r"\bI2b\b",
        "(I1b**2 - I2b)",
    ),
    Rewrite(
        "I2-plus",
        "I2 = (I1^2 + tr(C^2)) / 2, the minus of (I1^2 - tr(C^2)) / 2 lost (I1^2 - I2 for I2)",
        r"\bI2\b",
        "(I1**2 - I2)",
    ),
    Rewrite(
        "I2-diagonal",
        "tr(C^2) in I2 = (I1^2 - tr(C^2)) / 2 taken from the diagonal of C only (the off-diagonal "
        "entries dropped)",
        r"\bI2b\b",
        f"(J**(-4/3)*{_I2_DIAGONAL})",
    ),
    Rewrite(
        "I2-diagonal",
        "tr(C^2) in I2 = (I1^2 - tr(C^2)) / 2 taken from the diagonal of C only (the off-diagonal "
        "entries dropped)",
        r"\bI2\b",
        _I2_DIAGONAL,
    ),
    Rewrite(
        "I2-voigt",
        "tr(C^2) in I2 = (I1^2 - tr(C^2)) / 2 summed over the six Voigt entries of C, the "
        "off-diagonal ones counted once where tr(C^2) has them twice",
        r"\bI2b\b",
        f"(J**(-4/3)*{_I2_VOIGT})",
    ),
    Rewrite(
        "I2-inverse-trace",
        "I2 taken as tr C^-1 (the cofactor form I2 = tr cof C = det C tr C^-1 with its "
        "det C = J^2 dropped): I2b / J^2 used for I2b",
        r"\bI2b\b",
        "(I2b/J**2)",
    ),
    Rewrite(
        "I2-inverse-trace",
        "I2 taken as tr C^-1 (the cofactor form I2 = tr cof C = det C tr C^-1 with its "
        "det C = J^2 dropped)",
        r"\bI2\b",
        "(I2/J**2)",
    ),
    Rewrite("isochoric-I1", "the isochoric I1b used where the formula has I1", r"\bI1\b", "I1b"),
    Rewrite(
        "bulk-J-1", "k/2 (J-1)^2 for the bulk term k/2 (ln J)^2", r"ln\(J\)\*\*2", "(J - 1)**2"
    ),
    # ln J in another base (log10 for ln): every J term of the formula scaled non-linearly,
    # which the fit of U(J) per cell sees only as "a J-only energy differs".
    Rewrite(
        "log10",
        "log10 J (the base-10 logarithm, ln J / ln 10) used for the natural logarithm ln J",
        r"\bln\(J\)",
        f"(ln(J)/{float(np.log(10.0))!r})",
    ),
    Rewrite(
        "bulk-simo",
        "k/4 (J^2 - 1 - 2 ln J) for the bulk term k/2 (ln J)^2",
        r"/2\*ln\(J\)\*\*2",
        "/4*(J**2 - 1 - 2*ln(J))",
    ),
    # E = (C - I)/2 with the identity typed as a matrix of ones (np.ones for np.eye): each
    # off-diagonal strain shifted by -1/2 (the formula has each such entry once, as E12, E13,
    # E23; E21 ... are the same entries)
    Rewrite(
        "identity-ones",
        "E = (C - I)/2 with the identity typed as a matrix of ones: the off-diagonal strains "
        "E_ij shifted by -1/2",
        r"\bE(12|13|23|21|31|32)\b",
        r"(E\1 - 1/2)",
    ),
    # exp(-X) written as 1/exp(X), so that the rewrite needs no matching parenthesis
    Rewrite(
        "exp-sign",
        "exp(-X) for exp(X): the sign of the exponential's argument flipped (a decaying "
        "exponential typed where a growing one belongs)",
        r"\bexp\(",
        "1/exp(",
    ),
)


@dataclass(frozen=True)
class Variant:
    """rewrite: the mistake; expression: the rewritten formula; model: the user energy."""

    rewrite: Rewrite
    expression: str
    model: Any


def variants(model: Any) -> List[Variant]:
    """The variant energies of ``model`` (an empty list when its energy has no formula)."""
    from reference_fem.user_energy import UserEnergy

    base = _user(model) if isinstance(model, UserEnergy) else energy_expression(model)
    if base is None:
        return []
    expr, params = base
    out = []
    for rw in REWRITES:
        new = re.sub(rw.pattern, rw.replacement, expr)
        if new == expr:
            continue
        try:
            with warnings.catch_warnings():  # a variant is often pre-stressed: that is the point
                warnings.simplefilter("ignore")
                energy = UserEnergy(new, params, name=f"variant-{rw.code}")
        except ValueError:  # not finite at rest, or a parameter no longer used
            continue
        out.append(Variant(rw, new, energy))
    return out


def match_variant(
    model: Any,
    f: np.ndarray,
    K,
    within: Callable[[np.ndarray, Any], bool],
    evaluate: Callable[[Any], Tuple[np.ndarray, Any]],
) -> Optional[Tuple[Variant, Any]]:
    """The first variant of ``model`` whose oracle force and stiffness the engine's (f (n, 3),
    K (3n, 3n)) match: ``within(f_v, K_v)`` judges; ``evaluate(variant model)`` gives the
    oracle's (f_v, K_v). Returns (variant, (f_v, K_v)) or None.
    """
    for v in variants(model):
        try:
            fv, Kv = evaluate(v.model)
        except ValueError:  # the variant is not finite at this state
            continue
        if within(fv, Kv):
            return v, (fv, Kv)
    return None
