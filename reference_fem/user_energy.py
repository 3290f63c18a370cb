"""Strain energies the user writes: W as an expression of invariants and named parameters.

Example (Python)::

    UserEnergy("mu/2*(I1b-3) + K/2*(J-1)**2", {"mu": 1e3, "K": 1e4})

and from command-line strings (see :func:`user_energy_from_cli`)::

    --energy "mu/2*(I1b-3) + K/2*(J-1)**2" --param mu=1e3 --param K=1e4 [--fibre 1,0,0]

The syntax (one Python-style arithmetic expression; nothing else is accepted):

* numbers (``2``, ``0.5``, ``1e-3``), ``+ - * / **``, unary ``-``/``+``, parentheses;
* calls of ``ln(x)`` (``log(x)`` is the same natural logarithm), ``exp(x)``, ``sqrt(x)``
  and ``pow(x, y)``, with positional arguments only;
* the kinematic variables of :data:`VARIABLES` (C = F^T F, E = (C - I)/2, J = det F);
  ``I4`` = a.C a and ``I5`` = a.C^2 a use a fibre direction a: the ``fibre`` vector given
  (normalised to unit length, the same in every cell), or the first column of ``frame``, a
  fibre/sheet/normal frame per cell (m, 3, 3) or for the whole mesh (3, 3), the layout of
  Costa's frame. With neither, the energy can be built but not evaluated: a conformance kit
  gives it the mesh's helical field (common.frames), as it does Costa;
* the named parameters (each must be used; each must be a finite real number).

The expression is parsed with :mod:`ast` and checked against that whitelist before anything
is evaluated; nothing is ever passed to ``eval``. Anything else (attribute access, other
calls, keyword arguments, subscripts, lambdas, comprehensions, comparisons, strings ...) is
refused with a :class:`EnergySyntaxError` naming the offending text and its column (1-based).
A numeric literal used as an exponent must lie in [-MAX_LITERAL_EXPONENT, MAX_LITERAL_EXPONENT],
and the expression is limited to MAX_EXPRESSION_LENGTH characters, so that a few characters
cannot ask for an astronomically large computation.

Two translations of the same checked tree:

* :meth:`UserEnergy.ufl_density` gives W(F) as a UFL expression (the UFL oracle then
  differentiates it exactly as it does the built-in materials);
* :meth:`UserEnergy.density` evaluates W per cell from F (m, 3, 3) with NumPy (real or
  complex F: :meth:`UserEnergy.first_piola` uses a complex-step derivative, exact to
  round-off, for the checks below and for tests).

The state at rest (F = I) is examined when the energy is built:

* a non-finite W or first Piola stress P at rest is refused (ValueError): such an energy has
  no reference configuration to compare forces in;
* a non-zero P at rest is legal (a pre-stressed reference: the force on an undeformed mesh is
  not zero) but it is reported: ``prestressed`` is True, ``rest_stress`` holds P(I), and a
  :class:`PrestressWarning` is issued. "Non-zero" means |P(I)| > REST_STRESS_RTOL times the
  energy's small-strain modulus (|P| at a 1 % stretch divided by 0.01), so round-off in an
  expression such as ``mu*(I1b-3)`` does not count;
* a non-zero W at rest (e.g. ``mu/2*I1`` without the ``-3``) only shifts the total energy by
  a constant; it is reported in ``rest_energy`` and changes no force or stiffness.
"""

from __future__ import annotations

import ast
import math
import re
import types
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterable, Mapping, Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "UserEnergy",
    "EnergySyntaxError",
    "PrestressWarning",
    "parse_user_energy",
    "evaluate_formula",
    "user_energy_from_cli",
    "parse_param",
    "parse_fibre",
    "VARIABLES",
    "FUNCTIONS",
    "MAX_EXPRESSION_LENGTH",
    "MAX_LITERAL_EXPONENT",
    "REST_STRESS_RTOL",
]

MAX_EXPRESSION_LENGTH = 4000
MAX_LITERAL_EXPONENT = 64.0
REST_STRESS_RTOL = 1e-10

_COMPONENTS = {f"{s}{i + 1}{j + 1}": (s, i, j) for s in "CE" for i in range(3) for j in range(3)}

#: The kinematic variables an expression may use, with their meaning.
VARIABLES: Dict[str, str] = {
    "I1": "tr C",
    "I2": "((tr C)^2 - tr(C^2)) / 2",
    "I3": "det C = J^2",
    "J": "det F",
    "I1b": "J^(-2/3) I1 (isochoric)",
    "I2b": "J^(-4/3) I2 (isochoric)",
    "I4": "a.C a (needs a fibre a)",
    "I5": "a.C^2 a (needs a fibre a)",
    **{name: f"component ({i + 1},{j + 1}) of {s}" for name, (s, i, j) in _COMPONENTS.items()},
}
_FIBRE_VARIABLES = frozenset({"I4", "I5"})

#: The functions an expression may call, with their number of arguments.
FUNCTIONS: Dict[str, int] = {"ln": 1, "log": 1, "exp": 1, "sqrt": 1, "pow": 2}

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_UNARY = {ast.USub: "-", ast.UAdd: "+"}
_PARAM_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

# What an unsupported node is called in the error message.
_NODE_WORDS = {
    ast.Attribute: "attribute access",
    ast.Subscript: "subscript",
    ast.Lambda: "lambda",
    ast.ListComp: "comprehension",
    ast.SetComp: "comprehension",
    ast.DictComp: "comprehension",
    ast.GeneratorExp: "generator expression",
    ast.Compare: "comparison",
    ast.BoolOp: "boolean operator",
    ast.IfExp: "conditional expression",
    ast.NamedExpr: "assignment expression",
    ast.Starred: "starred argument",
    ast.JoinedStr: "f-string",
    ast.List: "list",
    ast.Tuple: "tuple",
    ast.Dict: "dict",
    ast.Set: "set",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
}


class EnergySyntaxError(ValueError):
    """An energy expression outside the accepted syntax; the message names the offending
    text and its column (1-based).
    """


class PrestressWarning(UserWarning):
    """A user energy whose first Piola stress at rest is not zero (legal, but the force on
    an undeformed mesh is then not zero).
    """


# -- parsing --------------------------------------------------------------------------------


def _where(expression: str, node: ast.AST) -> str:
    text = ast.get_source_segment(expression, node) or type(node).__name__
    if len(text) > 40:
        text = text[:37] + "..."
    return f"'{text}' at column {getattr(node, 'col_offset', 0) + 1}"


def _refuse(expression: str, node: ast.AST, what: str) -> EnergySyntaxError:
    return EnergySyntaxError(f"energy {expression!r}: {what}: {_where(expression, node)}")


def _literal(node: ast.AST) -> Optional[float]:
    """The value of a numeric literal, optionally signed; None if ``node`` is not one."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _literal(node.operand)
        if inner is None:
            return None
        return -inner if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    return None


def _check_tree(expression: str, node: ast.AST, names: frozenset) -> None:
    """Raise EnergySyntaxError unless every node of the tree is on the whitelist."""
    if isinstance(node, ast.Constant):
        if type(node.value) not in (int, float):  # bool, complex, str, bytes, None, Ellipsis
            raise _refuse(
                expression,
                node,
                f"only real numbers are allowed, not a {type(node.value).__name__}",
            )
        if not math.isfinite(float(node.value)):
            raise _refuse(expression, node, "number is not finite")
        return
    if isinstance(node, ast.Name):
        if node.id not in names:
            params = sorted(names - frozenset(VARIABLES))
            known = "I1, I2, I3, J, I1b, I2b, I4, I5, C11..C33, E11..E33"
            known += f"; parameters: {', '.join(params)}" if params else "; no parameters given"
            raise _refuse(expression, node, f"unknown name {node.id!r} (variables: {known})")
        return
    if isinstance(node, ast.BinOp):
        if type(node.op) not in _BINARY:
            raise _refuse(
                expression,
                node,
                f"operator {type(node.op).__name__} is not allowed (only + - * / **)",
            )
        if isinstance(node.op, ast.Pow):
            p = _literal(node.right)
            if p is not None and abs(p) > MAX_LITERAL_EXPONENT:
                raise _refuse(
                    expression,
                    node.right,
                    f"exponent {p:g} is outside [-{MAX_LITERAL_EXPONENT:g}, "
                    f"{MAX_LITERAL_EXPONENT:g}]",
                )
        _check_tree(expression, node.left, names)
        _check_tree(expression, node.right, names)
        return
    if isinstance(node, ast.UnaryOp):
        if type(node.op) not in _UNARY:
            raise _refuse(
                expression,
                node,
                f"operator {type(node.op).__name__} is not allowed (only unary - and +)",
            )
        _check_tree(expression, node.operand, names)
        return
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            allowed = ", ".join(FUNCTIONS)
            raise _refuse(expression, node.func, f"only calls of {allowed} are allowed")
        if node.keywords:
            raise _refuse(expression, node.keywords[0], "keyword arguments are not allowed")
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise _refuse(expression, arg, "starred arguments are not allowed")
        n = FUNCTIONS[node.func.id]
        if len(node.args) != n:
            raise _refuse(
                expression, node, f"{node.func.id} takes {n} argument(s), got {len(node.args)}"
            )
        if node.func.id == "pow":
            p = _literal(node.args[1])
            if p is not None and abs(p) > MAX_LITERAL_EXPONENT:
                raise _refuse(
                    expression,
                    node.args[1],
                    f"exponent {p:g} is outside [-{MAX_LITERAL_EXPONENT:g}, "
                    f"{MAX_LITERAL_EXPONENT:g}]",
                )
        for arg in node.args:
            _check_tree(expression, arg, names)
        return
    word = next((w for t, w in _NODE_WORDS.items() if isinstance(node, t)), type(node).__name__)
    raise _refuse(expression, node, f"{word} is not allowed")


def _parse(expression: str, names: frozenset) -> ast.expr:
    if not isinstance(expression, str):
        raise EnergySyntaxError(
            f"energy expression must be a string, got {type(expression).__name__}"
        )
    if not expression.strip():
        raise EnergySyntaxError("energy expression is empty")
    if len(expression) > MAX_EXPRESSION_LENGTH:
        raise EnergySyntaxError(
            f"energy expression has {len(expression)} characters; at most {MAX_EXPRESSION_LENGTH} "
            "are accepted"
        )
    if "\n" in expression or "\r" in expression:
        raise EnergySyntaxError("energy expression must be on one line")
    try:
        tree = ast.parse(expression.strip(), mode="eval")
    except SyntaxError as e:
        col = f" at column {e.offset}" if e.offset else ""
        raise EnergySyntaxError(
            f"energy {expression!r}: not a valid expression{col} ({e.msg})"
        ) from None
    except (RecursionError, MemoryError):
        raise EnergySyntaxError(f"energy {expression!r}: nested too deeply") from None
    expr = expression.strip()
    try:
        _check_tree(expr, tree.body, names)
    except RecursionError:
        raise EnergySyntaxError(f"energy {expression!r}: nested too deeply") from None
    return tree.body


def _used_names(tree: ast.AST) -> frozenset:
    # Function names are ast.Name too (the callee); they are not variables or parameters.
    callees = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    return frozenset(
        n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and id(n) not in callees
    )


# -- evaluation of the checked tree on a backend -------------------------------------------


class _Backend:
    """Primitive functions of one evaluation backend (NumPy or UFL)."""

    def __init__(self, ln: Callable, exp: Callable, sqrt: Callable):
        self.functions = {"ln": ln, "log": ln, "exp": exp, "sqrt": sqrt, "pow": lambda a, b: a**b}


def _evaluate(node: ast.expr, env: Mapping[str, Any], backend: _Backend):
    """Evaluate a whitelisted tree: ``env`` maps each name to its value on the backend."""
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.UnaryOp):
        v = _evaluate(node.operand, env, backend)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.BinOp):
        a = _evaluate(node.left, env, backend)
        b = _evaluate(node.right, env, backend)
        op = type(node.op)
        if op is ast.Add:
            return a + b
        if op is ast.Sub:
            return a - b
        if op is ast.Mult:
            return a * b
        if op is ast.Div:
            return a / b
        return a**b
    if isinstance(node, ast.Call):
        args = [_evaluate(a, env, backend) for a in node.args]
        return backend.functions[node.func.id](*args)
    raise AssertionError(f"unchecked node {type(node).__name__}")  # _check_tree refuses it


class _LazyKinematics(dict):
    """Variables computed on first use from ``make(name)`` (the form holds only what W uses)."""

    def __init__(self, make: Callable[[str], Any], fixed: Mapping[str, Any]):
        super().__init__(fixed)
        self._make = make

    def __missing__(self, name: str):
        value = self._make(name)
        self[name] = value
        return value


def _numpy_variable(name: str, F: np.ndarray, a: Optional[np.ndarray], cache: Dict[str, Any]):
    """Variable ``name`` for F (m, 3, 3), real or complex; values (m,)."""

    def get(n):
        if n not in cache:
            cache[n] = _numpy_variable(n, F, a, cache)
        return cache[n]

    if name == "C":
        return np.einsum("mki,mkj->mij", F, F)
    if name in _COMPONENTS:
        s, i, j = _COMPONENTS[name]
        C = get("C")
        return C[:, i, j] if s == "C" else 0.5 * (C[:, i, j] - (1.0 if i == j else 0.0))
    if name == "J":
        return np.linalg.det(F)
    if name == "I1":
        return np.einsum("mii->m", get("C"))
    if name == "I2":
        C = get("C")
        return 0.5 * (get("I1") ** 2 - np.einsum("mij,mji->m", C, C))
    if name == "I3":
        return np.linalg.det(get("C"))
    if name == "I1b":
        return get("J") ** (-2.0 / 3.0) * get("I1")
    if name == "I2b":
        return get("J") ** (-4.0 / 3.0) * get("I2")
    if name == "Ca":  # a is one direction (3,) or one per F (m, 3)
        C = get("C")
        return np.einsum("mij,mj->mi", C, np.broadcast_to(a, C.shape[:2]))
    if name == "I4":
        Ca = get("Ca")
        return np.einsum("mi,mi->m", Ca, np.broadcast_to(a, Ca.shape))
    if name == "I5":
        Ca = get("Ca")
        return np.einsum("mi,mi->m", Ca, Ca)
    raise AssertionError(name)


def _ufl_variable(name: str, F, a, get: Callable[[str], Any]):
    import ufl

    if name == "C":
        return F.T * F
    if name in _COMPONENTS:
        s, i, j = _COMPONENTS[name]
        C = get("C")
        return C[i, j] if s == "C" else 0.5 * (C[i, j] - (1.0 if i == j else 0.0))
    if name == "J":
        return ufl.det(F)
    if name == "I1":
        return ufl.tr(get("C"))
    if name == "I2":
        C = get("C")
        return 0.5 * (get("I1") ** 2 - ufl.tr(C * C))
    if name == "I3":
        return ufl.det(get("C"))
    if name == "I1b":
        return get("J") ** (-2.0 / 3.0) * get("I1")
    if name == "I2b":
        return get("J") ** (-4.0 / 3.0) * get("I2")
    if name == "Ca":
        return get("C") * a
    if name == "I4":
        return ufl.dot(a, get("Ca"))
    if name == "I5":
        Ca = get("Ca")
        return ufl.dot(Ca, Ca)
    raise AssertionError(name)


_NUMPY = _Backend(ln=np.log, exp=np.exp, sqrt=np.sqrt)


def evaluate_formula(expression: str, values: Mapping[str, Any]) -> Any:
    """An expression in the user-energy syntax evaluated with NumPy: ``values`` maps each name
    it uses (variables and parameters alike) to a number or an array (real or complex; arrays
    broadcast). The expression is checked against the same whitelist as an energy's, with the
    names of ``values`` as the only names; EnergySyntaxError otherwise.

    For formulas that are not energies (a derivative dW/dI1b written out, say), which
    :class:`UserEnergy` would examine at rest as if they were.
    """
    tree = _parse(expression, frozenset(values))
    return _evaluate(tree, values, _NUMPY)


# -- the energy ---------------------------------------------------------------------------


def _checked_params(params: Mapping[str, float]) -> Mapping[str, float]:
    if not isinstance(params, Mapping):
        raise ValueError(
            f"user energy: params must be a mapping name -> value, got {type(params).__name__}"
        )
    out = {}
    for name, value in params.items():
        if not isinstance(name, str) or not _PARAM_NAME.match(name):
            raise ValueError(f"user energy: parameter name {name!r} is not an identifier")
        if name in VARIABLES or name in FUNCTIONS:
            raise ValueError(f"user energy: parameter name {name!r} is a variable or function name")
        if isinstance(value, bool):
            raise ValueError(f"user energy: parameter {name} must be a real number, got {value!r}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(
                f"user energy: parameter {name} must be a real number, got {value!r}"
            ) from None
        if not math.isfinite(v):
            raise ValueError(f"user energy: parameter {name} must be finite, got {value!r}")
        out[name] = v
    return types.MappingProxyType(dict(sorted(out.items())))


def _checked_frame(frame) -> Optional[np.ndarray]:
    """A read-only float64 copy of a (3, 3) or (m, 3, 3) orthonormal frame, or None."""
    from reference_fem.validation import check_frame

    if frame is None:
        return None
    try:
        R = np.array(frame, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("user energy: frame must be an array of real numbers") from None
    if R.ndim not in (2, 3) or R.shape[-2:] != (3, 3) or R.size == 0:
        raise ValueError(f"user energy: frame must have shape (3, 3) or (m, 3, 3), got {R.shape}")
    try:
        check_frame(R, R.shape[0] if R.ndim == 3 else 1)  # finite and orthonormal, naming the cell
    except ValueError as exc:
        raise ValueError(f"user energy: {exc}") from None
    R.setflags(write=False)
    return R


def _checked_fibre(fibre) -> Optional[Tuple[float, float, float]]:
    if fibre is None:
        return None
    try:
        a = np.asarray(fibre, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"user energy: fibre must be 3 real numbers, got {fibre!r}") from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"user energy: fibre must be 3 finite real numbers, got {fibre!r}")
    if np.linalg.norm(a) == 0.0:
        raise ValueError("user energy: fibre direction is the zero vector")
    return tuple(float(v) for v in a)


@dataclass(frozen=True)
class UserEnergy:
    """A strain energy W(F) per unit rest volume, written by the user (module docstring).

    Attributes:
        expression: the formula, e.g. ``"mu/2*(I1b-3) + K/2*(J-1)**2"``.
        params: name -> value (floats; stored as a read-only copy). Every parameter must
            appear in the expression and every name of the expression must be a variable or
            a parameter.
        fibre: direction a of I4 and I5, 3 numbers (normalised before use), the same in
            every cell; only when the expression uses I4 or I5.
        name: a label for reports.
        frame: instead of ``fibre``, fibre/sheet/normal frames as columns, (3, 3) or one per
            cell (m, 3, 3), orthonormal; I4 and I5 use the first column, the fibre. Only when
            the expression uses I4 or I5. With neither fibre nor frame such an energy is built
            but refuses to be evaluated (:attr:`direction_missing`) until one is given, e.g. by
            ``dataclasses.replace(energy, frame=...)``.

    Derived at construction (not compared): ``rest_energy`` W(I), ``rest_stress`` P(I)
    (3, 3), ``prestressed`` (see the module docstring).

    Raises:
        EnergySyntaxError: the expression is outside the accepted syntax.
        ValueError: bad, missing or unused parameter, bad fibre or frame, both given,
            non-finite W or P at rest.
    """

    expression: str
    params: Mapping[str, float]
    fibre: Optional[Tuple[float, float, float]] = None
    name: str = "user energy"
    frame: Optional[np.ndarray] = None
    _tree: ast.expr = field(init=False, repr=False, compare=False)
    rest_energy: float = field(init=False, repr=False, compare=False)
    rest_stress: np.ndarray = field(init=False, repr=False, compare=False)
    prestressed: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        params = _checked_params(self.params)
        object.__setattr__(self, "params", params)
        object.__setattr__(self, "fibre", _checked_fibre(self.fibre))
        object.__setattr__(self, "frame", _checked_frame(self.frame))
        if self.fibre is not None and self.frame is not None:
            raise ValueError(
                "user energy: give a fibre direction (fibre=) or a frame (frame=), not both"
            )
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError("user energy: name must be a non-empty string")
        tree = _parse(self.expression, frozenset(VARIABLES) | frozenset(params))
        used = _used_names(tree)
        unused = sorted(set(params) - used)
        if unused:
            raise ValueError(
                f"user energy {self.expression!r}: parameter(s) {', '.join(unused)} not used in "
                "the expression"
            )
        needs_fibre = sorted(used & _FIBRE_VARIABLES)
        if (self.fibre is not None or self.frame is not None) and not needs_fibre:
            what = "fibre" if self.frame is None else "frame"
            raise ValueError(
                f"user energy {self.expression!r}: a {what} is given but neither I4 nor I5 is used"
            )
        object.__setattr__(self, "_tree", tree)
        self._examine_rest()

    def _key(self) -> tuple:
        frame = None if self.frame is None else (self.frame.shape, self.frame.tobytes())
        return (self.expression, tuple(self.params.items()), self.fibre, self.name, frame)

    def __hash__(self):
        return hash(self._key())

    def __eq__(self, other):
        # Written by hand: the generated one would compare the frame arrays elementwise.
        if not isinstance(other, UserEnergy):
            return NotImplemented
        return self._key() == other._key()

    @property
    def uses_fibre(self) -> bool:
        """True when the expression uses I4 or I5."""
        return bool(_used_names(self._tree) & _FIBRE_VARIABLES)

    @property
    def direction_missing(self) -> bool:
        """True when the expression uses I4 or I5 and neither a fibre nor a frame is given."""
        return self.uses_fibre and self.fibre is None and self.frame is None

    def directions(self, m: Optional[int] = None) -> Optional[np.ndarray]:
        """The unit fibre of I4 and I5: (3,) for one direction, (m, 3) for a frame per cell; None
        when the expression uses neither.

        Raises:
            ValueError: the direction is missing, or ``m`` differs from the frame's cell count.
        """
        if not self.uses_fibre:
            return None
        if self.direction_missing:
            raise ValueError(
                f"user energy {self.expression!r}: I4 and I5 need a fibre direction: "
                "give fibre= or frame= (a conformance kit gives the mesh's helical "
                "frame field)"
            )
        if self.frame is None:
            return self.unit_fibre
        if self.frame.ndim == 2:
            return self.frame[:, 0]
        if m is not None and m != self.frame.shape[0]:
            raise ValueError(
                f"user energy {self.expression!r}: {m} cells evaluated with a frame "
                f"of {self.frame.shape[0]} cells"
            )
        return self.frame[:, :, 0]

    # -- the rest state ---------------------------------------------------------------------
    def _examine_rest(self) -> None:
        eye = np.eye(3)[None]
        # W(I) and |P(I)| do not depend on the fibre's direction (I4 = I5 = 1 for every unit a);
        # one direction serves: the first cell's, or x when none is given yet.
        a = None
        if self.uses_fibre:
            missing = self.direction_missing
            a = np.array([1.0, 0.0, 0.0]) if missing else self.directions().reshape(-1, 3)[0]
        with np.errstate(all="ignore"):
            W0 = float(self._density(eye, a)[0])
            P0 = self._first_piola(eye, a)[0]
            stretch = np.diag([1.01, 1.0, 1.0])[None]
            modulus = float(np.linalg.norm(self._first_piola(stretch, a)[0] - P0)) / 0.01
        if not math.isfinite(W0):
            raise ValueError(
                f"user energy {self.expression!r}: W at rest (F = I) is not finite ({W0})"
            )
        if not np.all(np.isfinite(P0)):
            raise ValueError(
                f"user energy {self.expression!r}: the stress at rest (F = I) is not finite"
            )
        P0.setflags(write=False)
        object.__setattr__(self, "rest_energy", W0)
        object.__setattr__(self, "rest_stress", P0)
        norm = float(np.linalg.norm(P0))
        scale = modulus if math.isfinite(modulus) and modulus > 0 else 0.0
        prestressed = norm > REST_STRESS_RTOL * scale
        object.__setattr__(self, "prestressed", bool(prestressed))
        if prestressed:
            warnings.warn(
                PrestressWarning(self.rest_report()), stacklevel=4
            )  # the caller of UserEnergy(...)

    def rest_report(self) -> str:
        """One sentence on the state at rest (energy and first Piola stress at F = I)."""
        norm = float(np.linalg.norm(self.rest_stress))
        if self.prestressed:
            return (
                f"{self.name} ({self.expression}): the stress at rest is not zero (|P(I)| = "
                f"{norm:.6g}); forces on the undeformed mesh are not zero"
            )
        return (
            f"{self.name} ({self.expression}): stress-free at rest; W(I) = {self.rest_energy:.6g}"
        )

    # -- evaluations --------------------------------------------------------------------------
    @property
    def unit_fibre(self) -> Optional[np.ndarray]:
        """The fibre direction normalised to unit length (3,), or None."""
        if self.fibre is None:
            return None
        a = np.asarray(self.fibre, dtype=np.float64)
        return a / np.linalg.norm(a)

    @property
    def variables(self) -> Tuple[str, ...]:
        """The kinematic variables the expression uses."""
        return tuple(sorted(_used_names(self._tree) & set(VARIABLES)))

    def evaluate(
        self,
        variable: Callable[[str], Any],
        ln: Callable,
        exp: Callable,
        sqrt: Callable,
        constant: Optional[Callable[[float], Any]] = None,
    ):
        """W on any array or symbolic backend (how another library can run this energy).

        Args:
            variable: name in :data:`VARIABLES` -> its value on the backend (called once per
                name the expression uses; I4/I5 with the fibre of :meth:`directions`).
            ln, exp, sqrt: the backend's functions (``log`` is ``ln``; ``pow`` is ``**``).
            constant: turns each parameter value into what enters the result (default: the float).
        """
        wrap = (lambda v: v) if constant is None else constant
        # Parameters first; a variable is computed on its first use only (the result holds
        # only what W uses).
        env = _LazyKinematics(variable, {k: wrap(v) for k, v in self.params.items()})
        try:
            return _evaluate(self._tree, env, _Backend(ln=ln, exp=exp, sqrt=sqrt))
        except (OverflowError, ZeroDivisionError) as e:  # Python floats: constant sub-expressions
            raise ValueError(f"user energy {self.expression!r}: arithmetic error ({e})") from None

    def density(self, F: np.ndarray) -> np.ndarray:
        """W per unit rest volume for each F of ``F`` (m, 3, 3), real or complex; shape (m,).
        With a frame per cell, F holds one gradient per cell of that frame.

        Non-finite values (e.g. ln J with J <= 0) are returned as they come.
        """
        F = np.asarray(F)
        if F.ndim != 3 or F.shape[1:] != (3, 3):
            raise ValueError(f"user energy: F must have shape (m, 3, 3), got {F.shape}")
        return self._density(F, self.directions(F.shape[0]))

    def _density(self, F: np.ndarray, a: Optional[np.ndarray]) -> np.ndarray:
        """W (m,) for F (m, 3, 3) with unit fibre(s) a, (3,) or (m, 3), or None."""
        internal: Dict[str, Any] = {}  # C and C a, shared by the variables
        W = self.evaluate(lambda n: _numpy_variable(n, F, a, internal), np.log, np.exp, np.sqrt)
        return np.broadcast_to(W, F.shape[:1]).copy()

    def first_piola(self, F: np.ndarray, h: float = 1e-30) -> np.ndarray:
        """P = dW/dF (m, 3, 3) by complex-step differentiation of :meth:`density`: each entry
        is Im W(F + i h e_kl) / h, free of cancellation, so exact to round-off.
        """
        F = np.asarray(F, dtype=np.float64)
        return self._first_piola(F, self.directions(F.shape[0]), h)

    def _first_piola(self, F: np.ndarray, a: Optional[np.ndarray], h: float = 1e-30) -> np.ndarray:
        m = F.shape[0]
        Fc = np.repeat(F[:, None].astype(np.complex128), 9, axis=1)  # (m, 9, 3, 3)
        Fc.reshape(m, 9, 9)[:, np.arange(9), np.arange(9)] += 1j * h
        # Each cell's fibre once per perturbed copy of its F.
        a9 = a if a is None or a.ndim == 1 else np.repeat(a, 9, axis=0)
        W = self._density(Fc.reshape(m * 9, 3, 3), a9).reshape(m, 9)
        return (W.imag / h).reshape(m, 3, 3)

    def cell_energies(self, points: np.ndarray, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
        """V0 W(F) per P1 cell (m,): rest positions ``points`` (n, 3), ``cells`` (m, 4),
        current positions ``x`` (n, 3).
        """
        X = np.asarray(points, dtype=np.float64)
        x = np.asarray(x, dtype=np.float64)
        cells = np.asarray(cells)
        D0 = (X[cells[:, 1:]] - X[cells[:, :1]]).transpose(0, 2, 1)  # columns: edges from node 0
        D = (x[cells[:, 1:]] - x[cells[:, :1]]).transpose(0, 2, 1)
        F = D @ np.linalg.inv(D0)
        V0 = np.linalg.det(D0) / 6.0
        return V0 * self.density(F)

    def ufl_density(
        self, F, constant: Optional[Callable[[Any], Any]] = None, frame: Optional[Any] = None
    ):
        """W(F) as a scalar UFL expression for a UFL 3x3 ``F``. ``constant`` (optional)
        turns each parameter value into what enters the form (the oracle makes dolfinx
        Constants, so one compiled form serves every parameter set of one expression).
        ``frame`` (optional): a UFL 3x3 frame whose first column is the fibre, in place of the
        energy's own (the oracle passes a per-cell frame as a DG0 tensor Function).
        """
        import ufl

        a = None
        if frame is not None:
            a = ufl.as_vector([frame[i, 0] for i in range(3)])
        elif self.uses_fibre:
            if self.frame is not None and self.frame.ndim == 3:
                raise ValueError(
                    f"user energy {self.expression!r}: a frame per cell needs a mesh; "
                    "pass frame= as a UFL expression (UFLOracle does this with a DG0 "
                    "tensor Function)"
                )
            a = ufl.as_vector([float(v) for v in self.directions()])
        internal: Dict[str, Any] = {}  # C and C a, shared by the variables

        def get(n: str):
            if n not in internal:
                internal[n] = _ufl_variable(n, F, a, get)
            return internal[n]

        return self.evaluate(get, ufl.ln, ufl.exp, ufl.sqrt, constant)


def parse_user_energy(
    expression: str,
    params: Mapping[str, float],
    fibre: Optional[Sequence[float]] = None,
    name: str = "user energy",
) -> UserEnergy:
    """Build and validate a :class:`UserEnergy` (the same checks as the constructor)."""
    return UserEnergy(expression, params, None if fibre is None else tuple(fibre), name)


# -- command-line strings -------------------------------------------------------------------


def parse_param(text: str) -> Tuple[str, float]:
    """``"mu=1e3"`` -> ``("mu", 1000.0)``; a clear ValueError otherwise."""
    name, sep, value = str(text).partition("=")
    name, value = name.strip(), value.strip()
    if not sep or not name or not value:
        raise ValueError(f"--param {text!r}: expected NAME=VALUE, e.g. mu=1e3")
    if not _PARAM_NAME.match(name):
        raise ValueError(f"--param {text!r}: {name!r} is not a valid parameter name")
    try:
        v = float(value)
    except ValueError:
        raise ValueError(f"--param {text!r}: {value!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"--param {text!r}: value must be finite")
    return name, v


def parse_fibre(text: str) -> Tuple[float, float, float]:
    """``"1,0,0"`` -> ``(1.0, 0.0, 0.0)``; a clear ValueError otherwise."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(
            f"--fibre {text!r}: expected three numbers separated by commas, e.g. 1,0,0"
        ) from None
    if len(values) != 3:
        raise ValueError(f"--fibre {text!r}: expected three numbers, got {len(values)}")
    return values  # type: ignore[return-value]


def user_energy_from_cli(
    energy: str, params: Iterable[str] = (), fibre: Optional[str] = None, name: str = "user energy"
) -> UserEnergy:
    """The energy of ``--energy EXPR --param NAME=VALUE ... [--fibre a,b,c]``.

    A parameter given twice is refused (rather than silently keeping one of the values).
    """
    values: Dict[str, float] = {}
    for text in params:
        key, v = parse_param(text)
        if key in values:
            raise ValueError(f"--param {key} is given twice ({values[key]:g} and {v:g})")
        values[key] = v
    return UserEnergy(energy, values, None if fibre is None else parse_fibre(fibre), name)
