"""A derivative dW/dI written wrongly in a hand-written stress, the energy right.

Engines that write their stress by hand (a UMAT, a Cauchy stress in closed form, a force field's
second Piola-Kirchhoff routine) compute P = sum_k psi_k dI_k/dF, psi_k = dW/dI_k for each
invariant I_k the energy uses (I1, I2, J, I1b, I2b, I3), each psi_k typed as its own formula. A
mistake there leaves W right and makes the force wrong: the engine's energy matches the oracle's,
its force does not derive from it.

The energy's formula (:func:`conformance.diagnosis.variants.energy_expression`) is differentiated
symbolically (:mod:`conformance.diagnosis.formula_derivative`) and each psi_k rewritten the way a
hand derivation goes wrong, one change at a time: a sign before a term flipped or a minus lost,
the -1 of W's exp(X) - 1 carried into exp(X)'s derivative, a number doubled or halved (or an
integer one higher or lower: a power rule's coefficient), an exponent
off by one or with its sign lost, a parameter left out or another one used, an invariant used for
its isochoric version or the other way round; and psi_k as a whole with its sign flipped,
doubled, halved, dropped or multiplied by a power of J. Each rewrite predicts, per cell, the
stress P' = P + (psi_k' - psi_k) dI_k/dF, hence the force, with nothing fitted; the stiffness is
predicted five ways, as engines make it:

- the derivative of that force (a complex step or differences of the stress routine, a tangent
  derived from the same wrong psi_k): exact, by complex step of P' - P;
- the oracle's own (the tangent taken from the energy by automatic differentiation, or written
  separately and right);
- the oracle's plus the geometric part of the stress error, (D_a . dS D_b) Id with dS = F^-1 dP
  (a total-Lagrangian or force-field engine whose material tangent is its own formula, right, and
  whose geometric stiffness uses its wrong S);
- the derivative of that force computed for each cell's local node pairs a <= b and the blocks
  of b > a written as their transposes (an edge-based engine): the stress error's tangent is
  not symmetric, since that stress derives from no energy;
- the oracle's plus (psi_k' - psi_k) d2I_k/dF2: the wrong psi_k wherever the first derivative
  enters, the second derivatives d2W/dI2 typed apart and right (a spectral engine's principal
  block and pair terms, an invariant engine's W_k d2I_k/dC2 beside its W_kl dI_k dI_l).

A rewrite is named when the engine's energy agrees with the oracle's (or the engine gives none)
and one of its predictions brings force and stiffness within the case's tolerance, while the
oracle's own answer is outside it (else the state shows nothing). Rewrites that predict the same
answer are one cause said once (the first, the most specific); different predictions that fit
are shown as ambiguous.
"""

from __future__ import annotations

import ast
import functools
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    assemble,
    cell_kinematics,
    mirrored_pairs,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.diagnosis.formula_derivative import derivative, number
from conformance.diagnosis.variants import energy_expression
from conformance.judge.compare import Scales, Tolerances, errors
from conformance.judge.consistency import safe_norm
from reference_fem.user_energy import EnergySyntaxError, evaluate_formula

__all__ = [
    "StressRewrite",
    "GradientSlip",
    "IsochoricScaling",
    "stress_rewrites",
    "invariants",
    "invariant_gradients",
    "derivative_rewrite_findings",
    "derivative_rewrite_reading",
    "read_case",
]

#: The scalar invariants a hand-written stress is a sum over (the user-energy syntax's names).
INVARIANTS = ("I1", "I2", "I3", "J", "I1b", "I2b")
#: An invariant and the one it is confused with (isochoric or not).
_CONFUSED = {"I1b": "I1", "I1": "I1b", "I2b": "I2", "I2": "I2b"}
#: Extra powers of J a whole psi_k may carry (det B or J^2 used for J, a J left from a
#: push-forward).
_J_POWERS = ((-4, 3), (-1, 1), (-2, 3), (-1, 3), (1, 3), (2, 3), (1, 1), (4, 3))
#: Two predictions this close (relative, force and stiffness) are the same reading.
_SAME = 1e-9


@dataclass(frozen=True)
class StressRewrite:
    """One rewritten derivative: ``invariant`` I_k, dW/dI_k as written (``formula``) and as it
    should read (``right``), and the mistake in ``words``.
    """

    invariant: str
    formula: str
    right: str
    words: str


@dataclass(frozen=True)
class GradientSlip:
    """An invariant's gradient typed with its operands in another order, the same slip in every
    invariant built from it (dI2/dF and dI2b/dF share F C; dJ/dF, dI1b/dF, dI2b/dF share
    F^-T): ``slip`` names it (:data:`_GRADIENT_SLIPS`), ``derivatives`` ((invariant, dW/dI)) the
    energy's terms it reaches.
    """

    slip: str
    derivatives: Tuple[Tuple[str, str], ...]
    words: str

    @property
    def invariant(self) -> str:
        return " and ".join(k for k, _ in self.derivatives)


#: slip -> (the invariants whose gradient carries it, words). The right forms:
#: dI1/dF = 2 F, dI2/dF = 2 (I1 F - F C), dJ/dF = J F^-T.
_GRADIENT_SLIPS = {
    "CF": (("I2", "I2b"), "dI2/dF = 2 (I1 F - F C) typed with C F (a product's operands swapped)"),
    "FB": (("I2", "I2b"), "dI2/dF = 2 (I1 F - F C) typed with F B = F F F^T (B for C)"),
    "FT": (("I1", "I1b"), "dI1/dF = 2 F typed 2 F^T (F transposed in the gradient)"),
    "Finv": (
        ("J", "I3", "I1b", "I2b"),
        "dJ/dF = J F^-T typed J F^-1 (the inverse not transposed, in every F^-T of the stress)",
    ),
}


@dataclass(frozen=True)
class IsochoricScaling:
    """The isochoric part of the stress computed from J^q Bb where Bb = J^(-2/3) B belongs:
    each isochoric term's stress dW/dIkb dIkb/dF scaled by J^(q deg_k) (deg 1 for I1b, 2 for
    I2b, which is quadratic in Bb), with dW/dIkb (``derivatives``: (Ikb, formula)) evaluated at
    the invariants of J^q Bb when ``at_scaled``, else at the right ones.
    """

    q: Tuple[int, int]
    at_scaled: bool
    derivatives: Tuple[Tuple[str, str], ...]
    words: str

    @property
    def invariant(self) -> str:
        return " and ".join(k for k, _ in self.derivatives)


#: q of :class:`IsochoricScaling` and what it means (B the left Cauchy-Green tensor).
_ISOCHORIC_SCALINGS = (
    (
        (-2, 3),
        "J^(-4/3) B where J^(-2/3) B belongs (the isochoric factor J^(-2/3) applied twice, "
        "or det B = J^2 used for J in it)",
    ),
    ((2, 3), "B where J^(-2/3) B belongs (the isochoric factor J^(-2/3) left out of the stress)"),
    ((-1, 3), "J^(-1) B where J^(-2/3) B belongs (the isochoric factor's power written -1)"),
    ((1, 3), "J^(-1/3) B where J^(-2/3) B belongs (the isochoric factor's power halved)"),
)
_DEGREE = {"I1b": 1, "I2b": 2}
#: The C^-1 coefficient of dIkb/dC (J^p factor aside) as engines mistype it: (w, words).
_PROJECTION_SLIPS = {
    "I1b": (
        (-2 / 3, "-2/3 I1 C^-1 (I2b's coefficient)"),
        (1 / 3, "+1/3 I1 C^-1 (its sign lost)"),
        (0.0, "0 (left out)"),
        (
            -1 / 6,
            "-1/6 I1 C^-1 (halved: in dI1b/dF = J^(-2/3) (2 F - 2/3 I1 F^-T), the 2 of "
            "d(J^(-2/3))/dF dropped, -1/3 I1 F^-T)",
        ),
    ),
    "I2b": (
        (-1 / 3, "-1/3 I2 C^-1 (I1b's coefficient, or halved)"),
        (2 / 3, "+2/3 I2 C^-1 (its sign lost)"),
        (0.0, "0 (left out)"),
    ),
}
#: What a derivative is called where it has a name of its own in mechanics.
_ROLE = {"J": " (the volumetric stress: the pressure p = dW/dJ)"}


# ------------------------------------------------------------------ kinematics (complex-safe)
def invariants(F: np.ndarray) -> Dict[str, np.ndarray]:
    """I1, I2, I3, J, I1b, I2b per cell (m,) of F (m, 3, 3), real or complex (no conjugates:
    complex-step derivatives pass through).
    """
    C = np.swapaxes(F, 1, 2) @ F
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.trace(C @ C, axis1=1, axis2=2))
    J = np.linalg.det(F)
    return {
        "I1": I1,
        "I2": I2,
        "I3": J**2,
        "J": J,
        "I1b": J ** (-2.0 / 3.0) * I1,
        "I2b": J ** (-4.0 / 3.0) * I2,
    }


def invariant_gradients(
    F: np.ndarray, values: Dict[str, np.ndarray], slip: Optional[str] = None
) -> Dict[str, np.ndarray]:
    """dI/dF (m, 3, 3) of each invariant of :func:`invariants` (``values``), complex-safe;
    ``slip``: typed with one of :data:`_GRADIENT_SLIPS` (None: right).
    """
    Ft = np.swapaxes(F, 1, 2)
    Fi = np.linalg.inv(F)
    FiT = Fi if slip == "Finv" else np.swapaxes(Fi, 1, 2)
    C = Ft @ F
    I1, I2, J = values["I1"], values["I2"], values["J"]
    g1 = 2.0 * (Ft if slip == "FT" else F)
    FC = {"CF": C @ F, "FB": F @ F @ Ft}.get(slip, F @ C)
    g2 = 2.0 * (I1[:, None, None] * F - FC)
    w = lambda a: a[:, None, None]  # noqa: E731  (per-cell scalars against (m, 3, 3))
    return {
        "I1": g1,
        "I2": g2,
        "I3": w(2.0 * J**2) * FiT,
        "J": w(J) * FiT,
        "I1b": w(J ** (-2.0 / 3.0)) * (g1 - w(2.0 / 3.0 * I1) * FiT),
        "I2b": w(J ** (-4.0 / 3.0)) * (g2 - w(4.0 / 3.0 * I2) * FiT),
    }


# ------------------------------------------------------------------ the rewrites
class _Nodes(ast.NodeVisitor):
    """Every node of a tree in the order :class:`_At` counts them."""

    def __init__(self):
        self.nodes: List[ast.AST] = []

    def visit(self, node):
        self.nodes.append(node)
        self.generic_visit(node)


class _At(ast.NodeTransformer):
    """The tree with its ``target``-th node (in :class:`_Nodes`' order) replaced by make(node)."""

    def __init__(self, target: int, make: Callable[[ast.AST], ast.AST]):
        self.target, self.make, self.seen = target, make, -1

    def visit(self, node):
        self.seen += 1
        if self.seen == self.target:
            return self.make(node)
        return self.generic_visit(node)


def _parse(text: str) -> ast.expr:
    return ast.parse(text, mode="eval").body


def _replaced(text: str, index: int, make: Callable[[ast.AST], ast.AST]) -> str:
    tree = ast.Expression(_parse(text))  # parsed anew: no node shared with another rewrite
    return ast.unparse(ast.fix_missing_locations(_At(index, make).visit(tree)).body)


def _literal(node: ast.AST) -> Optional[float]:
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        v = _literal(node.operand)
        return None if v is None else -v
    return None


def _fmt(v: float) -> str:
    return ast.unparse(number(v))


def _node_rewrites(text: str, params: Tuple[str, ...]) -> Iterator[Tuple[str, str]]:
    """(rewritten formula, words) for each one-place change of the formula ``text``."""
    holder = _Nodes()
    holder.visit(ast.Expression(_parse(text)))
    for i, node in enumerate(holder.nodes):
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
            flip = ast.Sub() if isinstance(node.op, ast.Add) else ast.Add()
            new = ast.BinOp(node.left, flip, node.right)
            yield (
                _replaced(text, i, lambda n, new=new: new),
                f"the sign before {ast.unparse(node.right)} flipped: {ast.unparse(new)} where "
                f"{ast.unparse(node)} belongs",
            )
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            yield (
                _replaced(text, i, lambda n: n.operand),
                f"a minus sign lost: {ast.unparse(node.operand)} where {ast.unparse(node)} belongs",
            )
        elif isinstance(node, ast.Call) and node.func.id == "exp":
            new = ast.BinOp(node, ast.Sub(), ast.Constant(1))
            yield (
                _replaced(text, i, lambda n, new=new: new),
                f"{ast.unparse(new)} where {ast.unparse(node)} belongs (the -1 of the energy's "
                "exp(X) - 1 carried into its derivative)",
            )
        elif (
            isinstance(node, ast.BinOp)
            and isinstance(node.op, ast.Div)
            and _literal(node.left) == 1.0
        ):
            # 1 / X: the derivative of ln(X), which the chain rule multiplies in; dropped, the
            # term's derivative is X times what it should be
            yield (
                _replaced(text, i, lambda n: ast.Constant(1)),
                f"the factor {ast.unparse(node)} (the derivative of ln({ast.unparse(node.right)}) "
                "in the chain rule) lost",
            )
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            p = _literal(node.right)
            if p is None:
                continue
            for q, how in ((p - 1, "one lower"), (p + 1, "one higher"), (-p, "its sign lost")):
                if q == p:
                    continue
                new = ast.BinOp(node.left, ast.Pow(), number(q))
                yield (
                    _replaced(text, i, lambda n, new=new: new),
                    f"the exponent {_fmt(p)} written {_fmt(q)} ({how}): {ast.unparse(new)} where "
                    f"{ast.unparse(node)} belongs",
                )
        elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
            c = float(node.value)
            if c in (0.0, 1.0):
                continue
            for q in (2 * c, c / 2):
                yield (
                    _replaced(text, i, lambda n, q=q: number(q)),
                    f"the number {_fmt(c)} written {_fmt(q)} (a factor 2 "
                    f"{'too many' if abs(q) > abs(c) else 'lost'})",
                )
            if c == int(c) and abs(c) >= 3:
                # the power rule's coefficient taken from the lowered exponent (x^3 -> 2 x^2)
                # or the exponent's own slip carried into it; 2 -> 1 is the factor 2 above
                for q in (c - 1, c + 1):
                    yield (
                        _replaced(text, i, lambda n, q=q: number(q)),
                        f"the number {_fmt(c)} written {_fmt(q)} (one "
                        f"{'higher' if q > c else 'lower'}: a power rule's coefficient taken "
                        "from the wrong exponent)",
                    )
        elif isinstance(node, ast.Name) and node.id in params:
            yield (
                _replaced(text, i, lambda n: ast.Constant(1)),
                f"the parameter {node.id} left out",
            )
            for other in params:
                if other != node.id:
                    yield (
                        _replaced(text, i, lambda n, o=other: ast.Name(o, ast.Load())),
                        f"{other} used for {node.id}",
                    )
        elif isinstance(node, ast.Name) and node.id in _CONFUSED:
            other = _CONFUSED[node.id]
            yield (
                _replaced(text, i, lambda n, o=other: ast.Name(o, ast.Load())),
                f"{other} used for {node.id} in it",
            )


def _whole_rewrites(text: str) -> Iterator[Tuple[str, str]]:
    """(rewritten formula, words) for the derivative ``text`` scaled as a whole."""
    group = f"({text})"
    yield f"-{group}", "with its sign flipped"
    yield f"2*{group}", "doubled"
    yield f"{group}/2", "halved"
    yield "0", "left out (that term's stress missing)"
    for a, b in _J_POWERS:
        power = f"{a}" if b == 1 else f"{a}/{b}"
        yield f"{group}*J**({a}/{b})", f"multiplied by J^({power})"


def stress_rewrites(expression: str, params: Tuple[str, ...]) -> List[Any]:
    """The rewritten derivatives of the energy ``expression`` (user-energy syntax) in each of
    the invariants it uses; [] when it uses a variable that is not one of :data:`INVARIANTS`
    (C or E entries, I4, I5: no scalar chain rule through invariants).
    """
    try:
        tree = _parse(expression)
    except SyntaxError:
        return []
    callees = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and id(n) not in callees}
    used = [k for k in INVARIANTS if k in names]
    if names - set(params) - set(used):
        return []
    psi = {k: derivative(expression, k) for k in used}
    out, seen = [], set()
    for k in used:
        right = psi[k]
        if right == "0":
            continue
        name = f"dW/d{k}{_ROLE.get(k, '')}"
        specific = [(t, f"{name} with {w}") for t, w in _node_rewrites(right, params)]
        whole = [(t, f"{name} {w}") for t, w in _whole_rewrites(right)]
        for text, words in specific + whole:
            if text != right and (k, text) not in seen:
                seen.add((k, text))
                out.append(StressRewrite(k, text, right, words))
    if "I2b" in used:
        # dI2b/dF F^T = 2 dev(I1b Bb - Bb^2): the I1b there typed I1 = tr B adds
        # dW/dI2b (I1 - I1b) along dI1b/dF, whose F^T-push is 2 dev(Bb)
        psi1 = psi.get("I1b", "0")
        out.append(
            StressRewrite(
                "I1b",
                f"{psi1} + ({psi['I2b']})*(I1 - I1b)",
                psi1,
                "the I1b of the I2b stress, dev(I1b Bb - Bb^2), typed I1 = tr B (I1 for I1b in "
                "the isochoric invariant's gradient)",
            )
        )
    # dIkb/dC = J^(-2 deg/3) (dIk/dC - (deg/3) Ik C^-1): its C^-1 coefficient written w moves
    # 2 (w + deg/3) dW/dIkb Ikb / J onto dW/dJ (F C^-1 = F^-T, dJ/dF = J F^-T)
    right_j = psi.get("J", "0")
    for k in (k for k in used if k in _DEGREE):
        deg = _DEGREE[k]
        for w, how in _PROJECTION_SLIPS[k]:
            out.append(
                StressRewrite(
                    "J",
                    f"{right_j} + 2*({w} + {deg}/3)*({psi[k]})*{k}/J",
                    right_j,
                    f"the C^-1 term of d{k}/dC written {how} where -{deg}/3 {k[:2]} C^-1 belongs "
                    "(the isochoric projection of the stress)",
                )
            )
    for slip, (reached, words) in _GRADIENT_SLIPS.items():
        terms = tuple((k, psi[k]) for k in used if k in reached and psi[k] != "0")
        if terms:
            out.append(GradientSlip(slip, terms, f"{words} in the stress"))
    isochoric = tuple((k, psi[k]) for k in used if k in _DEGREE and psi[k] != "0")
    for q, words in _ISOCHORIC_SCALINGS if isochoric else ():
        for at_scaled in (False, True):
            where = "from them" if at_scaled else "from the right ones"
            out.append(
                IsochoricScaling(
                    q,
                    at_scaled,
                    isochoric,
                    f"the isochoric stress computed with {words}; its dW/dIkb evaluated {where}",
                )
            )
    return out


# ------------------------------------------------------------------ predictions
def _psi(formula: str, values: Dict[str, Any]) -> Optional[np.ndarray]:
    try:
        with np.errstate(all="ignore"):
            v = evaluate_formula(formula, values)
    except (EnergySyntaxError, ZeroDivisionError, OverflowError, KeyError):
        return None
    return v


@dataclass(frozen=True, eq=False)  # arrays: compared by identity
class _Cells:
    """Per cell of one F (m, 3, 3): the invariants and their gradients dI/dF, shared by every
    rewrite evaluated at that F.
    """

    F: np.ndarray
    inv: Dict[str, np.ndarray]
    grads: Dict[str, np.ndarray]

    @staticmethod
    def of(F: np.ndarray) -> "_Cells":
        inv = invariants(F)
        return _Cells(F, inv, invariant_gradients(F, inv))


@functools.singledispatch
def _stress_error(rw: Any, cells: _Cells, params: Dict[str, float]) -> Optional[np.ndarray]:
    """The stress error of the rewrite per cell (m, 3, 3), complex-safe; None where a
    derivative cannot be evaluated.
    """
    raise TypeError(type(rw).__name__)


@_stress_error.register
def _(rw: IsochoricScaling, cells: _Cells, params: Dict[str, float]) -> Optional[np.ndarray]:
    F, inv, grads = cells.F, cells.inv, cells.grads
    values = {**params, **inv}
    a, b = rw.q
    Jq = inv["J"] ** (a / b)
    scaled = dict(values)
    if rw.at_scaled:
        scaled.update({k: inv[k] * Jq**d for k, d in _DEGREE.items()})
    dP = np.zeros(F.shape, dtype=np.result_type(F, float))
    for k, formula in rw.derivatives:
        new, right = _psi(formula, scaled), _psi(formula, values)
        if new is None or right is None:
            return None
        d = np.broadcast_to(np.asarray(new) * Jq ** _DEGREE[k] - np.asarray(right), F.shape[:1])
        dP = dP + d[:, None, None] * grads[k]
    return dP


@_stress_error.register
def _(rw: GradientSlip, cells: _Cells, params: Dict[str, float]) -> Optional[np.ndarray]:
    """sum_k dW/dI_k (dI_k/dF as typed - dI_k/dF)."""
    values = {**params, **cells.inv}
    typed = invariant_gradients(cells.F, cells.inv, rw.slip)
    dP = np.zeros(cells.F.shape, dtype=np.result_type(cells.F, float))
    for k, formula in rw.derivatives:
        psi = _psi(formula, values)
        if psi is None:
            return None
        d = np.broadcast_to(np.asarray(psi), cells.F.shape[:1])
        dP = dP + d[:, None, None] * (typed[k] - cells.grads[k])
    return dP


@_stress_error.register
def _(rw: StressRewrite, cells: _Cells, params: Dict[str, float]) -> Optional[np.ndarray]:
    """(psi_k' - psi_k) dI_k/dF."""
    values = {**params, **cells.inv}
    new, right = _psi(rw.formula, values), _psi(rw.right, values)
    if new is None or right is None:
        return None
    d = np.broadcast_to(np.asarray(new) - np.asarray(right), cells.F.shape[:1])
    return d[:, None, None] * cells.grads[rw.invariant]


def _complex_step(F: np.ndarray, value: Callable[["_Cells"], Optional[np.ndarray]]):
    """The derivative d value / dF (m, 3, 3, 3, 3) by complex step, [k, I, l, L] =
    d value_kI / dF_lL: value (per-cell (3, 3) arrays of the cells' invariants, complex-safe)
    evaluated once on nine copies of each cell, one entry of F moved in each; None where value
    is None.
    """
    h = 1e-30
    m = F.shape[0]
    Fc = np.repeat(F[:, None].astype(np.complex128), 9, axis=1)
    Fc.reshape(m, 9, 9)[:, np.arange(9), np.arange(9)] += 1j * h
    with np.errstate(all="ignore"):
        v = value(_Cells.of(Fc.reshape(m * 9, 3, 3)))
    if v is None:
        return None
    # rows of the copies: (l, L) the perturbed entry; then the value's (k, I)
    return (v.imag / h).reshape(m, 3, 3, 3, 3).transpose(0, 3, 4, 1, 2)


def _stress_error_tangent(rw: Any, F: np.ndarray, params) -> Optional[np.ndarray]:
    """d(dP)/dF (m, 3, 3, 3, 3) by complex step, [k, I, l, L] = d dP_kI / dF_lL."""
    return _complex_step(F, lambda cells: _stress_error(rw, cells, params))


def _frozen_tangent(rw: Any, F: np.ndarray, params) -> Optional[np.ndarray]:
    """(psi_k' - psi_k) d2I_k/dF2 (m, 3, 3, 3, 3): the stress error's tangent with the wrong
    coefficient held fixed, as an engine has it that uses its psi_k' wherever the first
    derivative enters and types the second derivatives d2W/dI2 separately (right). None for a
    rewrite that is not one psi_k's.
    """
    if not isinstance(rw, StressRewrite):
        return None
    real = _Cells.of(F)
    values = {**params, **real.inv}
    new, right = _psi(rw.formula, values), _psi(rw.right, values)
    if new is None or right is None:
        return None
    d = np.broadcast_to(np.asarray(new) - np.asarray(right), F.shape[:1])
    dG = _complex_step(F, lambda cells: cells.grads[rw.invariant])
    return d[:, None, None, None, None] * dG


def _geometric(dP: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The geometric part delta_kl dS_IL of a stress error dP = F dS, (m, 3, 3, 3, 3)."""
    dS = np.linalg.solve(F, dP)
    return np.einsum("kl,mIL->mkIlL", np.eye(3), dS)


_TANGENTS = (
    ("consistent", "its stiffness the derivative of that force"),
    ("oracle", "its stiffness the energy's own (right)"),
    ("geometric", "its geometric stiffness from that stress, its material tangent right"),
    (
        "mirrored",
        "its stiffness the derivative of that force computed for each cell's local node pairs "
        "a <= b, the blocks of b > a written as their transposes (an edge-based engine)",
    ),
    (
        "frozen",
        "its tangent with that wrong dW/dI wherever the first derivative enters (the stress, "
        "the geometric stiffness, dW/dI d2I/dF2) and the second derivatives d2W/dI2 typed "
        "separately, right (a spectral or invariant engine's tangent)",
    ),
)


def derivative_rewrite_findings(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
    energy_given: bool = True,
) -> List[Finding]:
    """The rewritten derivatives whose predicted force and stiffness match the engine's
    (f (n, 3), K) where the oracle's (f_o, K_o) do not; several that predict differently:
    ambiguous.
    """
    base = energy_expression(model)
    if base is None:
        return []
    expression, params = base
    rewrites = stress_rewrites(expression, tuple(params))
    if not rewrites:
        return []
    V0, D, F = cell_kinematics(points, cells, x)
    n = points.shape[0]
    K = sp.csr_matrix(K)
    K_o = sp.csr_matrix(K_o)
    if tol.within(errors(f, K, None, f_o, K_o, 0.0, s), energy=False):
        return []
    matches: List[Tuple[Finding, np.ndarray, sp.csr_matrix]] = []
    at_F = _Cells.of(F)
    for rw in rewrites:
        dP = _stress_error(rw, at_F, params)
        if dP is None or not np.all(np.isfinite(dP)):
            continue
        df, _ = assemble(cells, n, piola_element_forces(V0, D, dP), None)
        f_p = f_o + df
        if safe_norm(np.asarray(f) - f_p) > tol.force * s.force:
            continue
        consistent = None  # the stress error's tangent, computed once per rewrite
        for how, words in _TANGENTS:
            if how == "oracle":
                K_p = K_o
            else:
                if how in ("consistent", "mirrored") and consistent is None:
                    consistent = _stress_error_tangent(rw, F, params)
                if how == "frozen":
                    A = _frozen_tangent(rw, F, params)
                else:
                    A = consistent if how in ("consistent", "mirrored") else _geometric(dP, F)
                if A is None or not np.all(np.isfinite(A)):
                    continue
                zero = np.zeros((cells.shape[0], 4, 3))
                Ke = tangent_element_matrices(V0, D, A)
                if how == "mirrored":
                    # the stress error's tangent is not symmetric (that stress derives from
                    # no energy): an engine that mirrors one triangle of a cell's blocks has
                    # the computed triangle's error in both
                    Ke = mirrored_pairs(Ke, "upper")
                K_p = K_o + assemble(cells, n, zero, Ke)[1]
            if tol.within(errors(f_p, K_p, None, f_o, K_o, 0.0, s), energy=False):
                continue  # the oracle's answer here: this state shows nothing of it
            e = errors(f, K, None, f_p, K_p, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            if any(_same(f_p, K_p, g, L, s) for _, g, L in matches):
                break
            matches.append((_finding(rw, words, e, _energy_words(energy_given)), f_p, K_p))
            break
    return ambiguous([m[0] for m in matches])


def _same(f1, K1, f2, K2, s: Scales) -> bool:
    e = errors(f1, K1, None, f2, K2, 0.0, s)
    return e.force <= _SAME and e.stiffness <= _SAME


def _energy_words(energy_given: bool) -> str:
    # Without the engine's energy, a rewritten derivative that is itself the derivative of
    # some energy W' cannot be told from that energy: say so rather than "the energy right".
    if energy_given:
        return "the energy right"
    return "your engine gives no energy, so an energy with that derivative would do the same"


@functools.singledispatch
def _finding(rw: Any, tangent: str, e, energy: str) -> Finding:
    raise TypeError(type(rw).__name__)


@_finding.register
def _(rw: IsochoricScaling, tangent: str, e, energy: str) -> Finding:
    a, b = rw.q
    return Finding(
        "stress-isochoric-scaling",
        f"the isochoric part of your stress scaled wrongly: {rw.words} ({energy})",
        FULL,
        f"the oracle's stress with its terms dW/dIkb dIkb/dF ({rw.invariant}) times J^({a}/{b}) "
        f"per power of Bb (nothing fitted), {tangent}: force error {e.force:.1e}, stiffness "
        f"error {e.stiffness:.1e}",
        {
            "q": f"{a}/{b}",
            "at_scaled": rw.at_scaled,
            "tangent": tangent,
            "residual": max(e.force, e.stiffness),
        },
    )


@_finding.register
def _(rw: GradientSlip, tangent: str, e, energy: str) -> Finding:
    return Finding(
        "stress-gradient-slip",
        f"your hand-written stress wrong: {rw.words} ({energy})",
        FULL,
        f"the oracle's stress with the gradients of {rw.invariant} typed so, each times its "
        f"dW/dI (nothing fitted), {tangent}: force error {e.force:.1e}, stiffness error "
        f"{e.stiffness:.1e}",
        {"slip": rw.slip, "tangent": tangent, "residual": max(e.force, e.stiffness)},
    )


@_finding.register
def _(rw: StressRewrite, tangent: str, e, energy: str) -> Finding:
    k = rw.invariant
    return Finding(
        "stress-derivative-rewritten",
        f"your hand-written stress wrong: {rw.words} ({energy})",
        FULL,
        f"dW/d{k} = {rw.formula} where {rw.right} belongs: the oracle's stress with its term "
        f"dW/d{k} d{k}/dF rewritten so (nothing fitted), {tangent}: force error {e.force:.1e}, "
        f"stiffness error {e.stiffness:.1e}",
        {
            "invariant": k,
            "formula": rw.formula,
            "right": rw.right,
            "tangent": tangent,
            "residual": max(e.force, e.stiffness),
        },
    )


def read_case(finder: Callable[..., List[Finding]], diag: Any, ci: Any, out: Any, ref: Any, s):
    """``diag`` with what ``finder`` finds on the case named first: finder(model, points, cells,
    positions, engine force, engine stiffness, oracle force, oracle stiffness, scales, tolerances).
    """
    case = (ci.model, ci.points, ci.cells, ci.positions)
    answers = (np.asarray(out.force), out.stiffness, np.asarray(ref.force), ref.stiffness)
    return named_first(diag, finder(*case, *answers, s, diag.tolerances))


def derivative_rewrite_reading(diag: Any, ci: Any, out: Any, ref: Any, s: Scales) -> Any:
    """``diag`` (a failed case nothing explained yet; its force wrong, or right at a state
    where the stress slip vanishes while its tangent does not) with a rewritten derivative
    named first when one explains it; unchanged when the engine's energy is wrong (then W
    itself differs) or nothing fits.
    """
    e = diag.errors.energy
    if e is not None and e > diag.tolerances.energy:
        return diag
    finder = functools.partial(derivative_rewrite_findings, energy_given=e is not None)
    return read_case(finder, diag, ci, out, ref, s)
