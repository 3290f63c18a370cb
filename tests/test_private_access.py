"""No module of mjed/ reaches into another module's private (underscore) names.

A module may use its own private names on any object (self._x, other._x of its own class);
what it may not do is read an underscore attribute that only another module defines, or
import an underscore name from another module: that is what public seams are for (e.g.
HyperelasticForceField.evaluate / assemble_force / assemble_stiffness).
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import List, Set

import pytest

MJED = Path(__file__).resolve().parents[1] / "mjed"


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _own_private_names(tree: ast.AST) -> Set[str]:
    """Underscore names the module itself defines: functions, classes, methods, module
    variables and attributes it assigns (self._x = ..., obj._x = ...).
    """
    names: Set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if _private(n)}


def foreign_private_accesses(source: str, filename: str = "<module>") -> List[str]:
    """Each access of an underscore name the module does not define, as 'file:line: what'."""
    tree = ast.parse(source, filename)
    own = _own_private_names(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) and node.attr not in own:
            found.append(f"{filename}:{node.lineno}: .{node.attr}")
        elif isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if _private(alias.name):
                    found.append(
                        f"{filename}:{node.lineno}: from {node.module} import {alias.name}"
                    )
    return found


def test_the_scan_finds_what_it_should():
    # It can fail: a foreign private attribute and a private import are reported ...
    bad = "from mjed.engine import _soa\n\ndef f(field):\n    return field._pattern\n"
    assert foreign_private_accesses(bad) == [
        "<module>:1: from mjed.engine import _soa",
        "<module>:4: ._pattern",
    ]
    # ... while a module's own private attributes, on self or on another instance, are not.
    good = (
        "class A:\n    def __init__(self):\n        self._x = 1\n\n    def same(self, other):\n    "
        "    return other._x\n"
    )
    assert foreign_private_accesses(good) == []


@pytest.mark.parametrize("path", sorted(MJED.rglob("*.py")), ids=lambda p: str(p.relative_to(MJED)))
def test_no_mjed_module_reads_another_modules_private_names(path):
    assert foreign_private_accesses(path.read_text(), str(path.relative_to(MJED.parent))) == []
