"""The derivative of a formula in the user-energy syntax, written as a formula.

An engine that writes its stress by hand writes dW/dI1b, dW/dJ, ... as formulas of their own,
and its mistakes are in those formulas, not in W. To rewrite them the way such engines get them
wrong, the diagnosis needs them as text: :func:`derivative` differentiates the syntax of
:mod:`reference_fem.user_energy` (numbers, names, ``+ - * / **``, unary minus, ``ln``/``log``,
``exp``, ``sqrt``, ``pow``) with respect to one name, the other names held fixed, and folds the
zeros and ones the rules leave (d(c x)/dx is ``c``, not ``0*x + c*1``) so that the result reads
like what an engineer writes. Numbers are kept exact where they are (an exponent p - 1 of a
literal p is computed, 1/3 - 1 written -0.6666666666666667).

Nothing here evaluates; :func:`reference_fem.user_energy.evaluate_formula` does.
"""

from __future__ import annotations

import ast
import functools
from typing import Optional

__all__ = ["derivative", "derivative_tree", "number"]


def number(value: float) -> ast.expr:
    """A literal (a negative one as unary minus, as the parser reads ``-2``)."""
    value = float(value)
    v = int(value) if value.is_integer() and abs(value) < 1e15 else value
    if value < 0:
        return ast.UnaryOp(ast.USub(), ast.Constant(-v))
    return ast.Constant(v)


def _value(node: ast.expr) -> Optional[float]:
    """The node's value when it is a literal (or minus a literal), else None."""
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.operand, ast.Constant):
        v = _value(node.operand)
        if v is not None:
            return -v if isinstance(node.op, ast.USub) else v
    return None


def _neg(a: ast.expr) -> ast.expr:
    v = _value(a)
    if v is not None:
        return number(-v)
    if isinstance(a, ast.UnaryOp) and isinstance(a.op, ast.USub):
        return a.operand
    return ast.UnaryOp(ast.USub(), a)


def _add(a: ast.expr, b: ast.expr) -> ast.expr:
    va, vb = _value(a), _value(b)
    if va is not None and vb is not None:
        return number(va + vb)
    if va == 0:
        return b
    if vb == 0:
        return a
    if isinstance(b, ast.UnaryOp) and isinstance(b.op, ast.USub):
        return ast.BinOp(a, ast.Sub(), b.operand)
    return ast.BinOp(a, ast.Add(), b)


def _sub(a: ast.expr, b: ast.expr) -> ast.expr:
    return _add(a, _neg(b))


def _mul(a: ast.expr, b: ast.expr) -> ast.expr:
    va, vb = _value(a), _value(b)
    if va is not None and vb is not None:
        return number(va * vb)
    if va == 0 or vb == 0:
        return number(0)
    if va == 1:
        return b
    if vb == 1:
        return a
    if va == -1:
        return _neg(b)
    if vb == -1:
        return _neg(a)
    return ast.BinOp(a, ast.Mult(), b)


def _div(a: ast.expr, b: ast.expr) -> ast.expr:
    va, vb = _value(a), _value(b)
    if va == 0:
        return number(0)
    if vb == 1:
        return a
    if va is not None and vb is not None and vb != 0:
        return number(va / vb)
    return ast.BinOp(a, ast.Div(), b)


def _pow(a: ast.expr, p: ast.expr) -> ast.expr:
    vp = _value(p)
    if vp == 0:
        return number(1)
    if vp == 1:
        return a
    return ast.BinOp(a, ast.Pow(), p)


def _call(name: str, *args: ast.expr) -> ast.expr:
    return ast.Call(ast.Name(name, ast.Load()), list(args), [])


def _uses(node: ast.expr, name: str) -> bool:
    return any(isinstance(n, ast.Name) and n.id == name for n in ast.walk(node))


def derivative_tree(node: ast.expr, name: str) -> ast.expr:
    """d(node)/d(name) as a tree, the other names held fixed."""
    if not _uses(node, name):
        return number(0)
    if isinstance(node, ast.Name):
        return number(1)  # the name itself (callees are not visited: see ast.Call below)
    if isinstance(node, ast.UnaryOp):
        d = derivative_tree(node.operand, name)
        return _neg(d) if isinstance(node.op, ast.USub) else d
    if isinstance(node, ast.BinOp):
        a, b = node.left, node.right
        da, db = derivative_tree(a, name), derivative_tree(b, name)
        op = node.op
        if isinstance(op, ast.Add):
            return _add(da, db)
        if isinstance(op, ast.Sub):
            return _sub(da, db)
        if isinstance(op, ast.Mult):
            return _add(_mul(da, b), _mul(a, db))
        if isinstance(op, ast.Div):
            if not _uses(b, name):
                return _div(da, b)
            return _sub(_div(da, b), _div(_mul(a, db), _pow(b, number(2))))
        if isinstance(op, ast.Pow):
            return _power_derivative(a, b, da, db, name)
    if isinstance(node, ast.Call):
        f = node.func.id
        args = node.args
        if f == "pow":
            a, b = args
            return _power_derivative(a, b, *(derivative_tree(x, name) for x in args), name)
        (a,) = args
        da = derivative_tree(a, name)
        if f in ("ln", "log"):
            return _div(da, a)
        if f == "exp":
            return _mul(node, da)
        if f == "sqrt":
            return _div(da, _mul(number(2), node))
    raise ValueError(f"cannot differentiate {ast.unparse(node)!r}")


def _power_derivative(a, b, da, db, name: str) -> ast.expr:
    """d(a^b): b a^(b-1) da for a b without ``name``, else a^b (db ln a + b da / a)."""
    if not _uses(b, name):
        vb = _value(b)
        lower = number(vb - 1) if vb is not None else _sub(b, number(1))
        return _mul(_mul(b, _pow(a, lower)), da)
    return _mul(
        ast.BinOp(a, ast.Pow(), b),
        _add(_mul(db, _call("ln", a)), _div(_mul(b, da), a)),
    )


@functools.lru_cache(maxsize=256)  # a pure function of two strings; readings ask it per case
def derivative(expression: str, name: str) -> str:
    """d(expression)/d(name) as a formula in the same syntax (``"0"`` when it does not use the
    name). Raises ValueError for what the syntax does not contain.
    """
    tree = ast.parse(expression.strip(), mode="eval").body
    return ast.unparse(derivative_tree(tree, name))
