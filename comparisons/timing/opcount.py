"""An operation-count model of force + stiffness per element, for MJED and the classical
Galerkin, derived from a material's declared MJED terms and from its classical law.

What it is for: the timing study compares the compiled MJED kernel with the compiled
classical kernel (mjed/compiled/codegen.py, reference_fem/classical_codegen.py). If both are
limited by arithmetic, the ratio of their times should follow the ratio of the operations
they execute; where it does not, memory traffic, branches or call overheads are at work, and
the study says so.

Counting rules (one cell, one force+stiffness evaluation, counted from the loops of the
compiled kernels as they are written, at a generic state with distinct eigenvalues):

- one flop per floating-point add, subtract, multiply or divide, and per square root;
- a libm call (log, exp, pow, expm1, log1p) counts ``TRANSCENDENTAL`` = 20 flops, about its
  cost in multiply-adds on x86-64;
- comparisons, branches, integer index arithmetic, loads and stores count nothing (the
  bandwidth floor of comparisons/timing/bandwidth.py is about memory);
- the 3x3 eigen-decomposition (Jacobi) counts ``JACOBI_SWEEPS`` = 4 sweeps of 3 rotations;
- assembly counts the additions into the per-edge and per-node sums; the ordered write of
  the CSR array is a copy and counts nothing.

MJED's count comes from the term list (mjed.terms types, via a registry keyed by type) and
the tangent slots the lowering builds from it (mjed/compiled/lowering.py), so a new material
is counted without touching this module unless it brings a new term type. The classical
count is made from the generated source of the law's kernel itself (:func:`source_flops`:
every binary operation not between literals, ``**`` and math.* as libm calls, eigh3_sym as
the Jacobi count, the larger branch of an if/else), so it follows the generator exactly.
Counted that way (:func:`mjed_source_flops`), the generated MJED kernels execute fewer flops
than MJED's hand-derived model gives (the model is 1.18x (Ogden) to 1.53x (St
Venant-Kirchhoff) the source count). The predicted ratio therefore takes both counts from the
generated sources (like with like); the hand model stays beside it, for its parts.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field
from typing import Callable, Dict, Tuple

import numpy as np

from mjed.fibre import FibreQuadratic
from mjed.materials.base import Material
from mjed.spectral import EigenPowerSum
from mjed.terms import (
    GreenLagrangeQuadratic,
    I1Power,
    JLogJ,
    JPower,
    LinearI2,
    LogPolynomial,
    Term,
    Unity,
)

__all__ = [
    "TRANSCENDENTAL",
    "JACOBI_SWEEPS",
    "OpCount",
    "mjed_flops",
    "classical_flops",
    "source_flops",
    "mjed_source_flops",
    "model",
]

TRANSCENDENTAL = 20
JACOBI_SWEEPS = 4
T = TRANSCENDENTAL
# One Jacobi rotation: theta, t, c, s (with two square roots) and three 3x3 row/column updates.
_ROTATION = 14 + 3 * 18
EIGEN = JACOBI_SWEEPS * (3 * _ROTATION + 6)
MATMUL3 = 45  # a 3x3 by 3x3 product
APPLY_4 = 60  # a 3x3 matrix applied to the four shape vectors


@dataclass(frozen=True)
class OpCount:
    """Flops per cell by part, and their total."""

    method: str
    parts: Dict[str, int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return int(sum(self.parts.values()))

    def to_dict(self) -> dict:
        return {"method": self.method, "parts": dict(self.parts), "total": self.total}


# ------------------------------------------------------------------ MJED: per term type
def _f_jpower(f: JPower) -> int:
    return 0 if f.p == 0.0 else T + 6


_F_COST: Dict[type, Callable] = {
    JPower: _f_jpower,
    LogPolynomial: lambda f: T + 12,
    JLogJ: lambda f: T + 8,
}

# (value + stress, tangent coefficients) of each invariant type.
_G_COST: Dict[type, Callable] = {
    Unity: lambda g: (0, 0),
    I1Power: lambda g: (3, 0) if g.n == 1 else (2 * T + 12, T + 5),
    LinearI2: lambda g: (1 + 9 * 3, 2),
    GreenLagrangeQuadratic: lambda g: (4 + 9 * 6 + 4, 1),
    FibreQuadratic: lambda g: (27 * 3 + 27 * 2 + 27 + 81 * 3, 0),
    # S from three powers; the exact tangent: three pair quotients, three diagonal limits, the
    # scaling.
    EigenPowerSum: lambda g: (3 * T + 6 + 9 * 9, 3 * 8 + 3 * 2 + 18),
}


def _lookup(obj, table: Dict[type, Callable], what: str):
    for cls in type(obj).__mro__:
        if cls in table:
            return table[cls]
    raise NotImplementedError(f"no operation count for the {what} {type(obj).__name__}")


def _varies(f) -> bool:
    """Whether f(J) is not a constant (so f' and f'' terms exist)."""
    return not (isinstance(f, JPower) and f.p == 0.0)


def mjed_flops(material: Material) -> OpCount:
    """The model of the compiled MJED kernel for ``material`` (see the module's rules)."""
    from mjed.compiled.lowering import lower_groups

    groups = material.decomposition()
    table = lower_groups(groups, np.zeros((1, 4, 3)))
    terms: Tuple[Term, ...] = tuple(t for g in groups for t in g.terms)
    stressed = [not isinstance(t.g, Unity) for t in terms]
    has_S = any(stressed)
    has_Sh = any(s and _varies(t.f) for s, t in zip(stressed, terms))
    has_h = any(_varies(t.f) for t in terms)
    need_eig = table.need_eig
    n_exp = int((table.group_kind != 0).sum())  # groups with a function of their sum
    slots = list(zip(table.slot_kind.tolist(), table.slot_ident.tolist()))
    n_first = sum(1 for k, _ in slots if k == 0)
    n_second = sum(1 for k, _ in slots if k == 1)
    n_spectral = sum(1 for k, _ in slots if k == 2)
    n_plain_slots = n_first + n_second

    parts: Dict[str, int] = {}
    parts["kinematics"] = 72 + 27 + 5 + 45 + 2 + 18 + 3 + (EIGEN if need_eig else 0)
    term_cost = 0
    for t in terms:
        value, tangent = _lookup(t.g, _G_COST, "invariant function")(t.g)
        term_cost += _lookup(t.f, _F_COST, "function of J")(t.f) + value + tangent + 6
        term_cost += 36 if not isinstance(t.g, Unity) else 0
        term_cost += 2 * len(t.g.tangent) + (18 if isinstance(t.g, EigenPowerSum) else 0)
    groups_cost = len(groups) * (2 * 27 + 2 * n_plain_slots + 4) + n_exp * (
        T + 1 + MATMUL3 + 18 + APPLY_4
    )
    parts["terms"] = term_cost + groups_cost
    parts["force"] = APPLY_4 + MATMUL3 + 4 * 3 * 8
    per_cell = APPLY_4  # S D_a
    per_cell += (MATMUL3 + APPLY_4) if has_Sh else 0
    for kind, ident in slots:
        if kind == 2:
            per_cell += 45 + 60  # F v_n and v_n . D_a
            continue
        per_cell += 4 * 3 * (5 if ident else 10)
        per_cell += 9 * 9 * 3 if kind == 1 else 0  # F M F^T
    per_edge = 3 + (5 if has_S else 0) + 27 * n_first + 46 * n_second + 189 * n_spectral
    per_edge += 54 if (has_Sh or has_h) else 0
    per_edge += 27 * n_exp + (6 if has_h else 0)  # h d2J: (h / 6) (x_d - x_c), not h F (D_a x D_b)
    parts["edge blocks"] = per_cell + 6 * per_edge
    # edge sums; node blocks K_aa as upper triangles (three blocks summed) subtracted into Dg
    parts["assembly"] = 6 * 9 + 4 * 6 * 2 + 4 * 9
    return OpCount("mjed", parts)


# ------------------------------------------------------------------ classical: from its generated
# source
# The part of the kernel a statement belongs to, by the name it assigns (the names of
# reference_fem.classical_codegen); every other statement is the law's (W, S, CC).
_CLASSICAL_PARTS = {
    "n": "kinematics",
    "D": "kinematics",
    "X": "kinematics",
    "F": "kinematics",
    "J": "kinematics",
    "C": "kinematics",
    "L": "kinematics",
    "idet": "kinematics",
    "Ci": "kinematics",
    "vol": "kinematics",
    "Sv": "force",
    "SD": "force",
    "force": "force",
    "CCv": "element matrix",
    "B": "element matrix",
    "CB": "element matrix",
    "g": "element matrix",
    "K": "element matrix",
    "ge": "assembly",
    "U": "assembly",
    "Dg": "assembly",
}
_NAME = re.compile(r"[A-Za-z]+")


def _is_constant(node: ast.AST) -> bool:
    """An expression of literals only (folded by the compiler: no run-time flop)."""
    if isinstance(node, ast.Constant):
        return True
    if isinstance(node, ast.UnaryOp):
        return _is_constant(node.operand)
    return isinstance(node, ast.BinOp) and _is_constant(node.left) and _is_constant(node.right)


class _Flops(ast.NodeVisitor):
    """Flops of one statement by the module's rules (``**`` and math.* are libm calls, the
    generic branch of a conditional expression, no index arithmetic).
    """

    def __init__(self) -> None:
        self.n = 0

    def visit_BinOp(self, node: ast.BinOp) -> None:
        if _is_constant(node):
            return
        self.n += T if isinstance(node.op, ast.Pow) else 1
        self.generic_visit(node)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        self.n += 1
        self.visit(node.value)

    def visit_Call(self, node: ast.Call) -> None:
        name = ast.unparse(node.func)
        self.n += T if name.startswith("math.") else (EIGEN if name == "eigh3_sym" else 0)
        self.generic_visit(node)

    def visit_IfExp(self, node: ast.IfExp) -> None:
        self.visit(node.orelse)  # e.g. Ogden's divided difference at distinct eigenvalues

    def visit_Subscript(self, node: ast.Subscript) -> None:
        pass  # loads and stores; index arithmetic


def source_flops(
    source: str, parts: Dict[str, str], default: str, skip: Tuple[str, ...] = ()
) -> Dict[str, int]:
    """Flops per cell of a generated kernel module, by part: the statements of its loop over
    cells (every ``if`` taken but those whose condition is in ``skip``, the larger branch of an
    ``if``/``else``: the two orientations of an edge block's scatter), each put in the part
    named by ``parts`` for the name it assigns (``default`` for the others). Calls to compiled
    helpers other than eigh3_sym (MJED's divided differences) count nothing.
    """
    function = ast.parse(source).body[-1]
    loop = next(node for node in function.body if isinstance(node, ast.For))

    def walk(statements) -> Dict[str, int]:
        counts: Dict[str, int] = {}
        for st in statements:
            if isinstance(st, ast.If) and ast.unparse(st.test) in skip:
                continue
            if isinstance(st, ast.If):
                body, other = walk(st.body), walk(st.orelse)
                for part, n in (
                    body if sum(body.values()) >= sum(other.values()) else other
                ).items():
                    counts[part] = counts.get(part, 0) + n
                continue
            target = st.targets[0] if isinstance(st, ast.Assign) else getattr(st, "target", None)
            part = (
                default
                if target is None
                else parts.get(_NAME.search(ast.unparse(target)).group(), default)
            )
            flops = _Flops()
            flops.visit(st)
            counts[part] = counts.get(part, 0) + flops.n
        return counts

    return walk(loop.body)


def classical_flops(material: Material) -> OpCount:
    """The count of the compiled classical kernel of ``material``'s classical law, made from
    its generated source (reference_fem.classical_codegen) by the module's rules.
    """
    from reference_fem.classical_codegen import classical_source
    from reference_fem.classical_compiled import lower_law
    from reference_fem.classical_materials import classical_law

    shape = lower_law(classical_law(material))[0]
    counts = source_flops(classical_source(shape), _CLASSICAL_PARTS, "law (S, CC)")
    order = ("kinematics", "law (S, CC)", "force", "element matrix", "assembly")
    return OpCount("classical", {part: counts.get(part, 0) for part in order})


def mjed_source_flops(material: Material) -> int:
    """The generated MJED kernel's flops per cell counted from its source by the same rules
    as the classical kernel's (the regularised diagonal, off by default, left out): a check
    of :func:`mjed_flops`, which is derived by hand from the terms.
    """
    from mjed.compiled.codegen import kernel_source
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape

    shape = kernel_shape(lower_groups(material.decomposition(), np.zeros((1, 4, 3))))
    return sum(source_flops(kernel_source(shape), {}, "all", skip=("regularize",)).values())


def model(material: Material) -> dict:
    """Both counts and the predicted classical/mjed ratio of compute-bound kernels.

    predicted_ratio compares like with like: both kernels counted from their generated
    sources by the same rules. hand_model_ratio uses MJED's count derived by hand from the
    declared terms (its parts explain where MJED's operations go; it over-counts the source).
    """
    m, c, src = mjed_flops(material), classical_flops(material), mjed_source_flops(material)
    return {
        "mjed": m.to_dict(),
        "mjed_source": src,
        "classical": c.to_dict(),
        "predicted_ratio": c.total / src,
        "hand_model_ratio": c.total / m.total,
    }
