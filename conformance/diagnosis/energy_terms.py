"""An energy the oracle can evaluate *differently*: one of its additive terms, or the whole of it
computed with a mistaken kinematic. The mechanism behind the term fit
(:mod:`conformance.diagnosis.term_fit`) and the kinematic variants
(:mod:`conformance.diagnosis.kinematics`).

Every energy with a formula reaches UFL the same way: a declared material's ``energy(p, k)``
(its declaration, ``mjed/materials/<material>.py``) on a namespace ``k`` of kinematic quantities,
a user energy's expression on its variables. Here both are run on :class:`Kinematics`, whose
quantities can be computed the way an engine gets them wrong (F transposed, the stretches for
their squares, the frame in the deformed configuration), and the resulting UFL expression can be

- **split** into its additive terms (sums expanded through products and quotients by factors that
  do not depend on the deformation; terms that do not depend on it dropped), each term carrying
  the parameters it reads;
- **rewritten**: every non-integer power of J (the isochoric powers J^(-2/3), J^(-4/3),
  J^(-alpha/3)) scaled by a factor, or the density weighted by J (the deformed volume).

:class:`conformance.diagnosis.transformed.TransformedEnergy` wraps a model with a :class:`Spec`
saying which; its UFL energy is registered with :mod:`reference_fem.energies`, so the oracle
(:class:`reference_fem.UFLOracle`) differentiates it exactly as it does the model's own energy.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

__all__ = [
    "declaration",
    "Spec",
    "exponent_key",
    "has_formula",
    "j_exponents",
    "model_frame_of",
    "split_terms",
    "symbolic",
    "symbolic_domain",
    "term_names",
    "term_parameters",
]


@dataclass(frozen=True)
class Spec:
    """How to evaluate a model's energy.

    term: the index of one additive term (None: the whole energy);
    transpose: F^T used for F (C and B confused);
    deformation: "inverse" (F^-1 used for F: the gradient of the map from the current cell to
    the rest one, dX/dx, for dx/dX), "symmetric" ((F + F^T)/2 used for F in C and the strains,
    J = det F kept: the rotation ignored, F taken for its stretch U), "reversed" (2 I - F: the
    displacements taken as u = X - x), "c-diagonal" (sqrt(diag C): the off-diagonal entries of C
    lost, everything then from diag C) or None (F);
    deformed_volume: the density weighted by J (integrated over the deformed volume);
    eigen_power: the power of the eigenvalues of C multiplied by this (2: eigenvalues of C taken as
    stretches; 0.5: stretches taken as eigenvalues of C);
    i1: "trC2" (I1 = tr(C^2), the squared stretches squared again), "trU" (I1 = sum of the
    stretches, the stretches for their squares), "trFF" (tr(F F): the transpose of C = F^T F
    lost) or "diagF" (F_11^2 + F_22^2 + F_33^2: tr C = sum_ij F_ij^2 from F's diagonal only),
    None: tr C;
    j_power: every non-integer power of J multiplied by this (1: unchanged); j_power_of: only the
    powers whose exponent prints as this (None: all);
    frame_deformed: the frame pushed forward, columns F R / |F R| (the deformed configuration);
    strain: the strain measure E read as "green" (None: (C - I)/2), "no-half" (C - I, the 1/2 of
    Green's strain dropped), "small" ((F + F^T)/2 - I, the linearised strain) or "isochoric"
    ((J^(-2/3) C - I)/2, Green's strain of the isochoric C_bar); only E changes;
    j_exponents: ((exponent, factor), ...): each non-integer power of J whose exponent prints as
    ``exponent`` (:func:`exponent_key`) taken as J^(factor x exponent), the factor entering the
    form as a parameter does (one compiled form for every factor: a fit of the exponents);
    j_out_of_exp: a non-integer power of J that multiplies an exponential's argument applied
    to the exponential term instead, exp(J^p X) taken as J^p (exp(X) - 1) + 1 (so that
    c (exp(J^p X) - 1) reads c J^p (exp(X) - 1)).
    """

    term: Optional[int] = None
    transpose: bool = False
    deformed_volume: bool = False
    eigen_power: float = 1.0
    i1: Optional[str] = None
    j_power: float = 1.0
    j_power_of: Optional[str] = None
    frame_deformed: bool = False
    j_exponents: Tuple[Tuple[str, float], ...] = ()
    strain: Optional[str] = None
    j_out_of_exp: bool = False
    deformation: Optional[str] = None

    def key(self) -> str:
        return repr(self)


def _user_energy_type():
    from reference_fem.user_energy import UserEnergy

    return UserEnergy


def declaration(model: Any):
    """The declaration of ``model``'s type (mjed/materials), or None (not a declared material)."""
    from mjed.materials.declaration import declaration_of

    if not dataclasses.is_dataclass(model):
        return None
    try:
        return declaration_of(type(model))
    except LookupError:
        return None


def has_formula(model: Any) -> bool:
    """A declared material or a user energy: an energy this module can rewrite and split."""
    return isinstance(model, _user_energy_type()) or declaration(model) is not None


def model_frame_of(model: Any) -> Optional[np.ndarray]:
    frame = getattr(model, "frame", None)
    return None if frame is None else np.asarray(frame, dtype=np.float64)


def _uses_frame(model: Any) -> bool:
    if isinstance(model, _user_energy_type()):
        return bool(model.uses_fibre)
    return any(f.name == "frame" for f in dataclasses.fields(model))


class Kinematics:
    """The namespace of the declared formulas (docs/conventions.md, "Kinematics"), computed as
    ``spec`` says; also the variables of a user energy (:meth:`variable`).
    """

    def __init__(self, F, frame, spec: Spec):
        import ufl

        from reference_fem.ogden_eigen import sum_of_eigenvalue_powers

        self._eps = sum_of_eigenvalue_powers
        self._spec = spec
        if spec.deformation == "inverse":
            F = ufl.inv(F)
        elif spec.deformation == "reversed":  # u = X - x: F = I - grad u
            F = 2.0 * ufl.Identity(3) - F
        elif spec.deformation == "c-diagonal":  # C's shear entries lost: U = sqrt(diag C)
            C = F.T * F
            F = ufl.as_matrix(
                [[ufl.sqrt(C[i, i]) if i == j else 0.0 for j in range(3)] for i in range(3)]
            )
        J = ufl.det(F)
        if spec.deformation == "symmetric":  # J kept: det F, which no rotation changes
            F = 0.5 * (F + F.T)
        if spec.transpose:
            F = F.T
        if spec.frame_deformed and frame is not None:
            FR = F * frame
            frame = ufl.as_matrix(
                [
                    [FR[i, j] / ufl.sqrt(sum(FR[k, j] ** 2 for k in range(3))) for j in range(3)]
                    for i in range(3)
                ]
            )
        self.exp, self.ln, self.tr = ufl.exp, ufl.ln, ufl.tr
        self.F = F
        self.C = F.T * F
        eye = ufl.Identity(3)
        if spec.strain == "no-half":
            self.E = self.C - eye
        elif spec.strain == "small":
            self.E = 0.5 * (F + F.T) - eye
        elif spec.strain == "isochoric":  # from C_bar = J^(-2/3) C: the decoupled habit
            self.E = 0.5 * (J ** (-2.0 / 3.0) * self.C - eye)
        else:
            self.E = 0.5 * (self.C - eye)
        if spec.i1 == "trC2":
            self.I1 = ufl.tr(self.C * self.C)
        elif spec.i1 == "trU":
            self.I1 = sum_of_eigenvalue_powers(self.C, 0.5)
        elif spec.i1 == "trFF":
            self.I1 = ufl.tr(F * F)
        elif spec.i1 == "diagF":
            self.I1 = F[0, 0] ** 2 + F[1, 1] ** 2 + F[2, 2] ** 2
        else:
            self.I1 = ufl.tr(self.C)
        self.I2 = 0.5 * (ufl.tr(self.C) ** 2 - ufl.tr(self.C * self.C))
        self.J = J
        self.lnJ = ufl.ln(J)
        self.I1b = J ** (-2.0 / 3.0) * self.I1
        self.I2b = J ** (-4.0 / 3.0) * self.I2
        self.frame = frame

    def eigenvalue_power_sum(self, C, q):
        return self._eps(C, q * self._spec.eigen_power)

    def variable(self, name: str, fibre):
        """A user energy's variable ``name`` (reference_fem.user_energy.VARIABLES)."""
        import ufl

        if name in ("C", "J", "I1", "I2", "I1b", "I2b"):
            return getattr(self, name)
        if name == "I3":
            return ufl.det(self.C)
        if len(name) == 3 and name[0] in "CE" and name[1:].isdigit():
            i, j = int(name[1]) - 1, int(name[2]) - 1
            return self.C[i, j] if name[0] == "C" else self.E[i, j]
        a = fibre
        if self.frame is not None:
            a = ufl.as_vector([self.frame[i, 0] for i in range(3)])
        Ca = self.C * a
        if name == "I4":
            return ufl.dot(a, Ca)
        if name == "I5":
            return ufl.dot(Ca, Ca)
        raise ValueError(f"unknown variable {name!r}")


class _Named:
    """Parameters read by name for a declared formula, each recorded with what enters the form."""

    def __init__(self, model: Any, constant: Optional[Callable[[Any], Any]]):
        self.model = model
        self.constant = constant
        self.entered: List[Tuple[Any, str]] = []

    def value(self, name: str) -> float:
        v = float(getattr(self.model, name))
        if not np.isfinite(v):
            raise ValueError(f"parameter {name} is not finite")
        return v

    def __call__(self, name: str):
        v = self.value(name)
        c = v if self.constant is None else self.constant(v)
        self.entered.append((c, name))
        return c


def _frame_expr(model: Any, frame, constant):
    """The frame the formula reads: the oracle's per-cell one, else the model's (3, 3), else I."""
    import ufl

    if frame is not None:
        return frame
    R = model_frame_of(model)
    if R is None or not _uses_frame(model):
        return ufl.Identity(3) if R is None else None
    if R.shape == (3, 3):
        return ufl.as_matrix(R.tolist()) if constant is None else constant(R)
    raise ValueError("a per-cell frame needs the oracle's frame Function")


def build(model: Any, F, frame, constant, spec: Spec):
    """(W as UFL, [(what entered the form, parameter name)]) of ``model`` evaluated as ``spec``
    says (the whole energy or one term).
    """
    import ufl

    W, entered = written_energy(model, F, frame, constant, spec)
    if spec.j_exponents:
        W = _refit_j_powers(W, dict(spec.j_exponents), entered, constant)
    if spec.j_power != 1.0:
        W = _scale_j_powers(W, spec.j_power, spec.j_power_of)
    if spec.j_out_of_exp:
        W = _j_power_out_of_exp(W)
    if spec.deformed_volume:
        W = ufl.det(F) * W
    if spec.term is not None:
        terms = split_terms(W, F)
        if spec.term >= len(terms):
            raise ValueError(f"term {spec.term} of {len(terms)}")
        W = terms[spec.term]
    return W, entered


def written_energy(model: Any, F, frame, constant, spec: Spec):
    """(W, entered) of ``model`` as its formula is written, on the kinematics ``spec`` says (F
    transposed, stretches for their squares, the strain measure, the frame deformed), before any
    rewriting of its powers of J, its volume or its terms (:func:`build` does those).
    """
    import ufl

    UE = _user_energy_type()
    entered: List[Tuple[Any, str]] = []
    if isinstance(model, UE):
        R = frame
        if R is None and model.frame is not None and np.asarray(model.frame).shape == (3, 3):
            R = ufl.as_matrix(np.asarray(model.frame, dtype=float).tolist())
        k = Kinematics(F, R, spec)
        fibre = None
        if model.uses_fibre and R is None:
            fibre = ufl.as_vector([float(v) for v in model.directions()])
        names = list(model.params)
        made: List[Any] = []

        def wrap(v):
            c = v if constant is None else constant(v)
            made.append(c)
            return c

        cache: Dict[str, Any] = {}

        def variable(n):
            if n not in cache:
                cache[n] = k.variable(n, fibre)
            return cache[n]

        W = model.evaluate(variable, ufl.ln, ufl.exp, ufl.sqrt, wrap)
        entered = list(zip(made, names))
    else:
        declared = declaration(model)
        if declared is None:
            raise ValueError(f"{type(model).__name__}: no declared energy formula")
        p = _Named(model, constant)
        k = Kinematics(F, _frame_expr(model, frame, constant), spec)
        W = declared.energy(p, k)
        entered = p.entered
    return W, entered


def _is_integer_literal(e) -> bool:
    from ufl.constantvalue import ScalarValue

    return isinstance(e, ScalarValue) and float(e) == int(float(e))


def j_power_exponents(W) -> List[str]:
    """The distinct non-integer exponents of J (as printed) in the UFL expression W."""
    from ufl.classes import Determinant, Power
    from ufl.corealg.traversal import unique_pre_traversal

    out: List[str] = []
    for node in unique_pre_traversal(W):
        if isinstance(node, Power) and isinstance(node.ufl_operands[0], Determinant):
            ex = node.ufl_operands[1]
            if not _is_integer_literal(ex) and str(ex) not in out:
                out.append(str(ex))
    return out


def _scale_j_powers(W, r: float, only: Optional[str]):
    """W with every non-integer power of J (or only the one printed as ``only``) multiplied by r."""
    from ufl.classes import Determinant
    from ufl.corealg.map_dag import map_expr_dag
    from ufl.corealg.multifunction import MultiFunction

    class Rewrite(MultiFunction):
        expr = MultiFunction.reuse_if_untouched

        def power(self, o, base, exponent):
            if (
                isinstance(base, Determinant)
                and not _is_integer_literal(exponent)
                and (only is None or str(o.ufl_operands[1]) == only)
            ):
                return base ** (r * exponent)
            return self.reuse_if_untouched(o, base, exponent)

    return map_expr_dag(Rewrite(), W)


def _factors(e) -> list:
    """The factors of a (nested) UFL product."""
    from ufl.classes import Product

    if isinstance(e, Product):
        return [f for o in e.ufl_operands for f in _factors(o)]
    return [e]


def _j_power_out_of_exp(W):
    """W with each exp(J^p X) (J^p a non-integer power of J among the argument's factors) taken
    as J^p (exp(X) - 1) + 1; unchanged where no exponential's argument has such a factor.
    """
    import functools
    import operator

    import ufl
    from ufl.classes import Determinant, Power
    from ufl.corealg.map_dag import map_expr_dag
    from ufl.corealg.multifunction import MultiFunction

    def is_j_power(f) -> bool:
        return (
            isinstance(f, Power)
            and isinstance(f.ufl_operands[0], Determinant)
            and not _is_integer_literal(f.ufl_operands[1])
        )

    class Rewrite(MultiFunction):
        expr = MultiFunction.reuse_if_untouched

        def exp(self, o, argument):
            factors = _factors(argument)
            powers = [f for f in factors if is_j_power(f)]
            if len(powers) != 1 or len(factors) < 2:
                return self.reuse_if_untouched(o, argument)
            rest = functools.reduce(operator.mul, [f for f in factors if f is not powers[0]])
            return powers[0] * (ufl.exp(rest) - 1.0) + 1.0

    return map_expr_dag(Rewrite(), W)


def exponent_key(exponent, entered: List[Tuple[Any, str]]) -> str:
    """A power of J's exponent as printed, each parameter by its name ("-1 * alpha / 3.0"): the
    same for every build of a formula, whatever object carries the parameter.
    """
    import re

    text = str(exponent)
    for c, name in entered:
        text = re.sub(re.escape(str(c)) + r"(?![\d}])", name, text)
    return text


def j_exponents(model: Any) -> List[Tuple[str, float]]:
    """The non-integer exponents of J in ``model``'s energy: [(:func:`exponent_key`, value)], in
    order of appearance (a parameter's exponent, Ogden's -alpha/3, at the model's values).
    """
    import ufl
    from ufl.classes import Determinant, FloatValue, Power
    from ufl.corealg.traversal import unique_pre_traversal

    W, entered, _ = symbolic(model, Spec(), "symbol")
    values = {c: FloatValue(_Named(model, None).value(n)) for c, n in entered}
    out: List[Tuple[str, float]] = []
    for node in unique_pre_traversal(W):
        if isinstance(node, Power) and isinstance(node.ufl_operands[0], Determinant):
            ex = node.ufl_operands[1]
            key = exponent_key(ex, entered)
            if _is_integer_literal(ex) or key in dict(out):
                continue
            value = ufl.replace(ex, values) if values else ex
            out.append((key, float(value)))
    return out


def _refit_j_powers(W, factors: Dict[str, float], entered, constant):
    """W with each power of J whose exponent's key is in ``factors`` taken to that factor times
    its exponent (the factor a parameter-like constant when ``constant`` is given).
    """
    from ufl.classes import Determinant
    from ufl.corealg.map_dag import map_expr_dag
    from ufl.corealg.multifunction import MultiFunction

    made: Dict[str, Any] = {}

    class Rewrite(MultiFunction):
        expr = MultiFunction.reuse_if_untouched

        def power(self, o, base, exponent):
            key = exponent_key(o.ufl_operands[1], entered)
            if isinstance(base, Determinant) and key in factors:
                if key not in made:
                    r = factors[key]
                    made[key] = r if constant is None else constant(r)
                return base ** (made[key] * exponent)
            return self.reuse_if_untouched(o, base, exponent)

    return map_expr_dag(Rewrite(), W)


_SYMBOLIC: list = []


def symbolic_domain():
    """One symbolic UFL mesh of P1 tetrahedra (for :func:`symbolic`)."""
    return _symbolic_objects()[0]


def _symbolic_objects():
    """(domain, displacement, per-cell frame): created once, so that two symbolic builds of
    one formula print alike.
    """
    import ufl

    if not _SYMBOLIC:
        cell = ufl.tetrahedron
        domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell, 1))
        u = ufl.Coefficient(ufl.FunctionSpace(domain, ufl.VectorElement("Lagrange", cell, 1)))
        R = ufl.Coefficient(ufl.FunctionSpace(domain, ufl.TensorElement("DG", cell, 0)))
        _SYMBOLIC.extend([domain, u, R])
    return tuple(_SYMBOLIC)


def symbolic(model: Any, spec: Spec, constant: Optional[Callable[[Any], Any]] = None):
    """(W, entered, F) of ``model`` as ``spec`` says on a symbolic P1 tetrahedron (plain UFL, no
    mesh, nothing compiled): to count and label the terms, or to tell whether a variant changes
    the formula at all. ``constant`` as in :func:`build` (None: parameters as plain numbers;
    "symbol": a new UFL symbol for each).
    """
    import ufl

    domain, u, cell_frame = _symbolic_objects()
    F = ufl.Identity(3) + ufl.grad(u)
    R = model_frame_of(model)
    frame = cell_frame if R is not None and R.ndim == 3 else None
    if constant == "symbol":

        def constant(v):
            return ufl.Constant(domain, shape=np.shape(v))

    W, entered = build(model, F, frame, constant, spec)
    return W, entered, F


def _depends(e, u) -> bool:
    from ufl.algorithms.analysis import extract_coefficients

    return any(c is u or c == u for c in extract_coefficients(e))


def split_terms(W, F) -> list:
    """The additive terms of W that depend on the deformation (UFL expressions), in a fixed
    order: sums expanded through products and quotients by factors that do not depend on it.
    """
    return additive_parts(W, F)[0]


def additive_parts(W, F) -> Tuple[list, list]:
    """(the terms of :func:`split_terms`, the additive terms that do not depend on the
    deformation, such as a rest constant): together they sum to W.
    """
    from ufl.algorithms.analysis import extract_coefficients
    from ufl.classes import Division, Product, Sum

    coeffs = extract_coefficients(F)
    u = coeffs[0] if coeffs else None

    def dep(e) -> bool:
        return u is not None and _depends(e, u)

    def expand(e) -> list:
        if isinstance(e, Sum):
            a, b = e.ufl_operands
            return expand(a) + expand(b)
        if isinstance(e, Product):
            a, b = e.ufl_operands
            if not dep(a):
                return [a * t for t in expand(b)]
            if not dep(b):
                return [t * b for t in expand(a)]
        if isinstance(e, Division):
            a, b = e.ufl_operands
            if not dep(b):
                return [t / b for t in expand(a)]
        return [e]

    parts = expand(W)
    return [t for t in parts if dep(t)], [t for t in parts if not dep(t)]


def term_parameters(term, entered: List[Tuple[Any, str]]) -> Tuple[str, ...]:
    """The parameter names whose constants appear in ``term``, in the order they entered."""
    from ufl.algorithms.analysis import extract_type
    from ufl.classes import Constant

    present = extract_type(term, Constant)
    names: List[str] = []
    for c, name in entered:
        if any(c is x for x in present) and name not in names:
            names.append(name)
    return tuple(names)


def formula_terms(text: str) -> List[Tuple[str, str]]:
    """The top-level additive terms of a formula written as text: [(sign "+" or "-", the term
    as written)]. A sign inside parentheses, after an operator or in a number's exponent (1e-3)
    does not split.
    """
    out: List[Tuple[str, str]] = []
    depth, start, sign = 0, 0, "+"
    prev = ""  # the previous character that is not a space
    for i, ch in enumerate(text):
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch in "+-" and depth == 0:
            exponent = prev in "eE" and i >= 2 and text[: i - 1].rstrip()[-1:].isdigit()
            if prev and prev not in "+-*/^(,=" and not exponent:
                body = text[start:i].strip()
                if body:
                    out.append((sign, body))
                sign, start = ch, i + 1
            elif not prev:
                sign, start = ch, i + 1
        if not ch.isspace():
            prev = ch
    body = text[start:].strip()
    if body:
        out.append((sign, body))
    return out


def _identifiers(text: str) -> set:
    import re

    return set(re.findall(r"[A-Za-z_][A-Za-z_0-9]*", text))


def _declared_texts(model: Any) -> Optional[Tuple[str, Optional[str], List[str]]]:
    """(the energy as written, its volumetric part as written or None, the parameter names) of a
    declared material or a user energy; None when there is no written formula.
    """
    if isinstance(model, _user_energy_type()):
        return model.expression, None, list(model.params)
    declared = declaration(model)
    if declared is None or not getattr(declared, "formula", None):
        return None
    names = [f.name for f in dataclasses.fields(model) if f.name != "frame"]
    return declared.formula, declared.volumetric_formula, names


def _kind(body: str, volumetric: Optional[str], anisotropic: bool) -> Optional[str]:
    """The term's kind as the declaration writes it: isochoric, volumetric, anisotropic or None."""
    import re

    flat = " ".join(body.split())
    if volumetric is not None and any(
        " ".join(b.split()) == flat for _, b in formula_terms(volumetric)
    ):
        return "volumetric"
    if anisotropic:
        return "anisotropic"
    # The isochoric invariants of docs/conventions.md, or a power -p/3 of J on them (Ogden's).
    if re.search(r"\bI[12]b\b|J\^\(-[^()]*/3\)", flat):
        return "isochoric"
    return None


#: Functions a written term and a split term are matched on besides their parameters.
_FUNCTIONS = {"exp": ("Exp",), "ln": ("Ln",)}


def _functions_of_text(body: str) -> set:
    words = _identifiers(body)
    return {f for f in _FUNCTIONS if f in words or (f == "ln" and "log" in words)}


def _functions_of_term(term) -> set:
    from ufl.corealg.traversal import unique_pre_traversal

    kinds = {type(node).__name__ for node in unique_pre_traversal(term)}
    return {f for f, classes in _FUNCTIONS.items() if kinds & set(classes)}


def _match_written(split: List[Tuple[set, set]], written: List[Tuple[set, set]]):
    """For each split term (parameters, functions), the index of the written term it comes from,
    or None: the one assignment of the split terms to the written ones (one to one when there
    are as many) in which every pair shares its parameters and the written term has every
    function the split term applies; else each split term's only compatible written term.
    """
    import itertools

    def fits(u: Tuple[set, set], w: Tuple[set, set]) -> bool:
        shares = bool(u[0] & w[0]) if u[0] or w[0] else True
        return shares and u[1] <= w[1]

    ok = [[j for j, w in enumerate(written) if fits(u, w)] for u in split]
    if len(split) == len(written) and len(split) <= 7:
        perms = [
            p
            for p in itertools.permutations(range(len(split)))
            if all(p[i] in ok[i] for i in range(len(split)))
        ]
        if len(perms) == 1:
            return list(perms[0])
    return [c[0] if len(c) == 1 else None for c in ok]


def term_names(model: Any) -> List[Optional[str]]:
    """Each additive term of ``model``'s energy (in the order of :func:`split_terms`) named by
    its formula as the material declares it (or the user wrote it), with its kind where the
    declaration says it: "the isochoric term - c1 c2 / 2 (I2b - 3)". None for a term the written
    formula cannot be matched to (by the parameters it reads and the functions, exp and ln, it
    applies: :func:`_match_written`); "part k of m" when one written term gave several.
    """
    texts = _declared_texts(model)
    if texts is None:
        return []
    formula, volumetric, params = texts
    W, entered, F = symbolic(model, Spec(), "symbol")
    terms = split_terms(W, F)
    split = [(set(term_parameters(t, entered)), _functions_of_term(t)) for t in terms]
    written = formula_terms(formula)
    match = _match_written(
        split, [(_identifiers(b) & set(params), _functions_of_text(b)) for _, b in written]
    )
    if isinstance(model, _user_energy_type()):
        fibre = bool(model.uses_fibre)
    else:
        fibre = _uses_frame(model)
    names: List[Optional[str]] = []
    for i, j in enumerate(match):
        if j is None:
            names.append(None)
            continue
        sign, body = written[j]
        reads_fibre = fibre and (
            not isinstance(model, _user_energy_type()) or bool({"I4", "I5"} & _identifiers(body))
        )
        kind = _kind(body, volumetric, reads_fibre)
        name = f"the {kind + ' ' if kind else ''}term {'- ' if sign == '-' else ''}{body}"
        parts = [k for k, m in enumerate(match) if m == j]
        if len(parts) > 1:
            name += f" (part {parts.index(i) + 1} of {len(parts)}"
            name += f"{_series_part(body, parts.index(i), len(parts))})"
        names.append(name)
    return names


_SERIES = re.compile(r"sum_\{(\w)=(\d+)\.\.(\d+)\}\s*")


def _series_part(body: str, index: int, count: int) -> str:
    """The words added to a part's label when ``body`` is a written series sum_{i=a..b} whose
    b - a + 1 terms are the ``count`` parts: ": the series term i = 5, mu c_5 N^(1-5) (I1b^5 -
    3^5)" (the index value put in, so that the part reads as the series term it is); else "".
    """
    m = _SERIES.search(body)
    if m is None or int(m.group(3)) - int(m.group(2)) + 1 != count:
        return ""
    name, value = m.group(1), str(int(m.group(2)) + index)
    rest = body[: m.start()] + body[m.end() :]
    term = re.sub(rf"(?<![A-Za-z0-9]){name}(?![A-Za-z0-9])", value, rest)
    return f": the series term {name} = {value}, {term}"
