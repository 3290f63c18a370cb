"""What a material declares, once, in its own file; every registry is read from here.

A :class:`Declaration` holds everything the suite needs to know about one material type:

- ``material``: the frozen, validated dataclass of its parameters, whose ``decomposition()``
  gives the MJED terms (what the engine evaluates);
- ``formula``, ``notes`` and ``parameters``: W, what its symbols mean, and its parameters, as
  the table of docs/conventions.md shows them (:func:`docs_table_row`);
- ``default``: the parameter set used when none is given (``common.cases``);
- ``energy``: W written from its formula against a math namespace (:class:`FormulaNamespace`),
  never from the terms; the oracle binds the namespace to UFL and differentiates W;
- ``volumetric`` (and ``volumetric_formula``): its J-only part, the same way, or None;
- ``classical``: the classical element's form of the law (:mod:`mjed.materials.classical_forms`),
  from which the classical element builds S and its tangent;
- ``aliases`` (command-line spellings) and ``sofa`` (SOFA's name and ParameterSet order);
- ``order``: its place in the declaration order (the docs table, ``--material all``, every
  study's tables);
- ``ranges``: each parameter's valid range for the tests to draw from, ``(low, high)`` or a list
  of the values to choose among; ``examples``: named parameter sets that make every term of
  the energy matter (the tests' fixtures; the default when none is given).

:func:`declare` checks a declaration and registers it (a missing or ill-typed piece is an
error naming the material and the piece); :func:`declarations` lists them in declaration
order; :func:`declaration_of` finds the one of a type (or of its nearest declared base).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Dict, Mapping, Optional, Protocol, Tuple

from mjed.materials import classical_forms
from mjed.materials.base import Material

__all__ = [
    "FormulaNamespace",
    "Declaration",
    "declare",
    "declarations",
    "declaration_of",
    "docs_table_row",
    "docs_table",
    "DOCS_TABLE_HEADER",
]


class FormulaNamespace(Protocol):
    """What an energy formula may use (the oracle binds it to UFL).

    Scalars: ``I1``, ``I2``, ``J``, ``lnJ``, ``I1b`` = J^(-2/3) I1, ``I2b`` = J^(-4/3) I2.
    Matrices (3x3, with ``.T``, ``*`` as the matrix product and ``[i, j]``): ``C``, ``E``,
    and ``frame`` (columns fibre, sheet, normal; the identity when the material has none).
    Functions: ``exp``, ``ln``, ``tr`` and ``eigenvalue_power_sum(C, q)`` = sum_i lambda_i^q
    over the eigenvalues lambda_i of C.
    """

    I1: Any
    I2: Any
    J: Any
    lnJ: Any
    I1b: Any
    I2b: Any
    C: Any
    E: Any
    frame: Any

    def exp(self, x: Any) -> Any: ...

    def ln(self, x: Any) -> Any: ...

    def tr(self, A: Any) -> Any: ...

    def eigenvalue_power_sum(self, C: Any, q: Any) -> Any: ...


#: ``formula(p, k) -> W``: p(name) is a parameter as it enters the formula (p.value(name) its
#: float, for checks), k the namespace.
Formula = Callable[[Callable[[str], Any], FormulaNamespace], Any]


@dataclass(frozen=True)
class Declaration:
    """One material, declared once (see the module docstring for each field)."""

    material: type
    formula: str
    parameters: str
    default: Material
    energy: Formula
    volumetric: Optional[Formula]
    volumetric_formula: Optional[str]
    classical: Callable[[Any], Any]
    notes: str = ""
    aliases: Tuple[str, ...] = ()
    sofa: Optional[Tuple[str, Tuple[str, ...]]] = None
    order: int = 1000
    ranges: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    examples: Mapping[str, Material] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        who = getattr(self.material, "__name__", repr(self.material))
        if not (isinstance(self.material, type) and issubclass(self.material, Material)):
            raise TypeError(f"declaration of {who}: material must be a Material subclass")
        if not dataclasses.is_dataclass(self.material):
            raise TypeError(
                f"declaration of {who}: the material must be a (frozen) dataclass of its parameters"
            )
        for name in ("formula", "parameters"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name).strip():
                raise TypeError(f"declaration of {who}: {name} (the docs table's text) is missing")
        if type(self.default) is not self.material:
            raise TypeError(f"declaration of {who}: default must be a {who}, got {self.default!r}")
        for name in ("energy", "classical"):
            if not callable(getattr(self, name)):
                raise TypeError(
                    f"declaration of {who}: {name} must be a function, got {getattr(self, name)!r}"
                )
        if (self.volumetric is None) != (self.volumetric_formula is None):
            raise TypeError(
                f"declaration of {who}: volumetric and volumetric_formula go together "
                "(both None for a material without a J-only part)"
            )
        if self.volumetric is not None and not callable(self.volumetric):
            raise TypeError(f"declaration of {who}: volumetric must be a function")
        form = self.classical(self.default)
        if not isinstance(form, classical_forms.FORMS):
            known = ", ".join(f.__name__ for f in classical_forms.FORMS)
            raise TypeError(
                f"declaration of {who}: classical must return a form of "
                f"mjed.materials.classical_forms ({known}), got {form!r}"
            )
        fields = {f.name for f in dataclasses.fields(self.material)}
        required = {
            f.name
            for f in dataclasses.fields(self.material)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        }
        if not required <= set(self.ranges) <= fields:
            raise TypeError(
                f"declaration of {who}: ranges must give every parameter without a default "
                f"({sorted(required)}) and name only parameters ({sorted(fields)}), "
                f"got {sorted(self.ranges)}"
            )
        for name, rng in self.ranges.items():
            interval = isinstance(rng, tuple) and len(rng) == 2 and rng[0] < rng[1]
            if not (interval or (isinstance(rng, list) and rng)):
                raise TypeError(
                    f"declaration of {who}: range of {name} must be (low, high) or a list of "
                    f"values, got {rng!r}"
                )
        for label, example in self.examples.items():
            if type(example) is not self.material:
                raise TypeError(f"declaration of {who}: example {label} must be a {who}")
        if self.sofa is not None:
            unknown = [n for n in self.sofa[1] if n not in fields]
            if unknown:
                raise TypeError(
                    f"declaration of {who}: SOFA order names unknown parameters {unknown}"
                )

    @property
    def name(self) -> str:
        return self.material.__name__


_DECLARATIONS: Dict[type, Declaration] = {}


def declare(declaration: Declaration) -> Declaration:
    """Register ``declaration``; a type or a name declared twice is an error."""
    if not isinstance(declaration, Declaration):
        raise TypeError(f"declare needs a Declaration, got {declaration!r}")
    if declaration.material in _DECLARATIONS or declaration.name in {
        d.name for d in _DECLARATIONS.values()
    }:
        raise ValueError(f"material {declaration.name} is already declared")
    _DECLARATIONS[declaration.material] = declaration
    return declaration


def declarations() -> Tuple[Declaration, ...]:
    """Every declared material, in declaration order (``order``, then the order declared)."""
    return tuple(sorted(_DECLARATIONS.values(), key=lambda d: d.order))


def declaration_of(material_type: type) -> Declaration:
    """The declaration of ``material_type`` or of its nearest declared base class.

    Raises:
        LookupError: naming the type when it has none.
    """
    for cls in material_type.__mro__:
        if cls in _DECLARATIONS:
            return _DECLARATIONS[cls]
    raise LookupError(
        f"material type {material_type.__module__}.{material_type.__qualname__} is not declared; "
        "declare it with mjed.materials.declaration.declare (see docs/organisation.md)"
    )


#: The header of the materials table (docs/conventions.md, written by the site build); its
#: rows: :func:`docs_table_row`.
DOCS_TABLE_HEADER = ("| material | parameters | W | J-only part |", "|---|---|---|---|")


def docs_table_row(declaration: Declaration) -> str:
    """The material's row of the table in docs/conventions.md ("The materials")."""
    w = f"`{declaration.formula}`" + (f", {declaration.notes}" if declaration.notes else "")
    vol = f"`{declaration.volumetric_formula}`" if declaration.volumetric_formula else "none"
    return f"| `{declaration.name}` | {declaration.parameters} | {w} | {vol} |"


def docs_table() -> str:
    """The whole materials table of docs/conventions.md, one row per declared material."""
    return "\n".join(DOCS_TABLE_HEADER + tuple(docs_table_row(d) for d in declarations()))
