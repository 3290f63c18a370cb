"""Strain energy densities W(F) written directly in UFL, one function per material type.

This module is the "oracle" side of the verification: every energy is typed in from its
formula in docs/conventions.md and nothing else. Each built-in material's formula lives in
its declaration (``mjed/materials/<material>.py``, its ``energy``), written against a
namespace of invariants and functions that :class:`UFLNamespace` binds to UFL; it reads the
material's *parameters* and never its MJED terms (mjed.terms, mjed.engine, mjed.fibre,
mjed.spectral), and UFL differentiates it.

Dispatch is on the material's type through a public registry: :func:`register_energy`
declares the UFL energy of a type (subclasses inherit it), :func:`energy_formula` finds it,
and :func:`strain_energy_density` builds the expression. Every declared material is
registered from its declaration when this module is imported; another module may register
its own types the same way (e.g. a user-written energy), without editing this file::

    from reference_fem.energies import register_energy

    @register_energy(MyMaterial)
    def _my_energy(p, F, frame):
        mu = p("mu")                      # a parameter, as it enters the formula
        return 0.5 * mu * (ufl.tr(F.T * F) - 3.0)

``F`` is a UFL 3x3 expression (F = I + grad u); the result is a scalar UFL expression, per unit rest
volume. Parameters enter as plain numbers by default, or through a ``constant`` factory
(the oracle makes dolfinx Constants): then the compiled forms do not depend on the parameter
values and FFCx compiles each material type once, not once per parameter set.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

import numpy as np
import ufl

from mjed.materials import declarations
from mjed.materials.declaration import Formula
from reference_fem.ogden_eigen import sum_of_eigenvalue_powers
from reference_fem.user_energy import UserEnergy

__all__ = [
    "Parameters",
    "EnergyFunction",
    "EnergyFormula",
    "register_energy",
    "energy_formula",
    "supported_materials",
    "strain_energy_density",
    "UFLNamespace",
    "declared_energy",
]


class Parameters:
    """A material's parameters, read by name: ``p.value(name)`` as a float (for checks),
    ``p(name)`` as it enters the formula (a number, or what ``constant`` makes of it).

    Args:
        material: the material object (``p.material``).
        constant: optional factory applied to every parameter (e.g. a dolfinx Constant).
        overrides: parameter values used instead of the material's (e.g. ``{"k0": 0.0}`` to
            drop a bulk term); the material itself is never changed.
    """

    def __init__(
        self,
        material: Any,
        constant: Optional[Callable[[Any], Any]] = None,
        overrides: Optional[Mapping[str, float]] = None,
    ):
        self.material = material
        self.constant = constant
        self.overrides = dict(overrides or {})

    def value(self, name: str) -> float:
        m = self.material
        label = type(m).__name__  # for messages only
        if name in self.overrides:
            got = self.overrides[name]
        elif hasattr(m, name):
            got = getattr(m, name)
        else:
            raise ValueError(f"{label}: missing parameter {name!r}")
        try:
            v = float(got)
        except (TypeError, ValueError):
            raise ValueError(
                f"{label}: parameter {name} must be a real number, got {got!r}"
            ) from None
        if not math.isfinite(v):
            raise ValueError(f"{label}: parameter {name} must be finite, got {v!r}")
        return v

    def wrap(self, value):
        return value if self.constant is None else self.constant(value)

    def __call__(self, name: str):
        return self.wrap(self.value(name))


#: f(p, F, frame) -> W: parameters, the deformation gradient (UFL 3x3) and the optional UFL
#: frame (None unless the formula takes one).
EnergyFunction = Callable[[Parameters, Any, Any], Any]


@dataclass(frozen=True)
class EnergyFormula:
    """The registered UFL energy of one material type.

    function: see :data:`EnergyFunction`. takes_frame: the formula accepts an explicit UFL
    frame (one rotation per cell, which the oracle supplies as a DG0 tensor Function).
    """

    material_type: type
    function: EnergyFunction
    takes_frame: bool = False


_REGISTRY: Dict[type, EnergyFormula] = {}


def register_energy(
    material_type: type, *, takes_frame: bool = False
) -> Callable[[EnergyFunction], EnergyFunction]:
    """Decorator: declare ``function`` as the UFL energy of ``material_type`` (and of its
    subclasses that have no energy of their own). Registering a type twice is an error, so
    two modules cannot silently disagree on one material.
    """
    if not isinstance(material_type, type):
        raise TypeError(f"register_energy needs a type, got {material_type!r}")

    def decorate(function: EnergyFunction) -> EnergyFunction:
        if material_type in _REGISTRY:
            raise ValueError(f"a UFL energy is already registered for {material_type.__qualname__}")
        _REGISTRY[material_type] = EnergyFormula(material_type, function, takes_frame)
        return function

    return decorate


def energy_formula(material_type: type) -> EnergyFormula:
    """The registered formula of ``material_type`` or of its nearest registered base class.

    Raises:
        ValueError: naming the type when no UFL energy is registered for it.
    """
    for cls in material_type.__mro__:
        if cls in _REGISTRY:
            return _REGISTRY[cls]
    known = ", ".join(t.__qualname__ for t in _REGISTRY)
    raise ValueError(
        f"no UFL energy for material type {material_type.__module__}.{material_type.__qualname__}; "
        f"register one with reference_fem.energies.register_energy (registered: {known})"
    )


def supported_materials() -> Tuple[type, ...]:
    """The material types with a registered UFL energy, in registration order."""
    return tuple(_REGISTRY)


def strain_energy_density(
    material: Any,
    F: ufl.core.expr.Expr,
    *,
    frame: Optional[Any] = None,
    constant: Optional[Callable[[Any], Any]] = None,
    overrides: Optional[Mapping[str, float]] = None,
) -> ufl.core.expr.Expr:
    """W(F) per unit rest volume, as a scalar UFL expression.

    Args:
        material: an instance of a type with a registered energy (``mjed.materials``
            dataclasses, or a type registered with :func:`register_energy`).
        F: the deformation gradient, a UFL 3x3 expression.
        frame: a UFL 3x3 rotation (columns fibre, sheet, normal) overriding the material's
            ``frame``, for formulas registered with ``takes_frame`` (Costa); needed when the
            material holds one rotation per cell.
        constant: factory applied to every parameter (see :class:`Parameters`).
        overrides: parameter values used instead of the material's, e.g. ``{"k0": 0.0}``.

    Raises:
        ValueError: no energy for the material's type, frame given to a formula that takes
            none, missing or non-finite parameter.
    """
    formula = energy_formula(type(material))
    if frame is not None and not formula.takes_frame:
        raise ValueError(
            "frame= is only meaningful for materials with a fibre frame, not "
            f"{type(material).__qualname__}"
        )
    return formula.function(Parameters(material, constant, overrides), F, frame)


class UFLNamespace:
    """The formula namespace of :mod:`mjed.materials.declaration` bound to UFL: the
    quantities every formula is written in (docs/conventions.md, "Kinematics") and the
    functions it may call.
    """

    exp = staticmethod(ufl.exp)
    ln = staticmethod(ufl.ln)
    tr = staticmethod(ufl.tr)
    eigenvalue_power_sum = staticmethod(sum_of_eigenvalue_powers)

    def __init__(self, F: ufl.core.expr.Expr, frame: Any = None):
        self.C = F.T * F  # right Cauchy-Green tensor
        self.E = 0.5 * (self.C - ufl.Identity(3))  # Green-Lagrange strain
        self.I1 = ufl.tr(self.C)
        self.I2 = 0.5 * (self.I1**2 - ufl.tr(self.C * self.C))
        self.J = ufl.det(F)
        self.lnJ = ufl.ln(self.J)
        self.I1b = self.J ** (-2.0 / 3.0) * self.I1
        self.I2b = self.J ** (-4.0 / 3.0) * self.I2
        self.frame = frame


def _frame(p: Parameters, frame) -> ufl.core.expr.Expr:
    """The fibre/sheet/normal frame R (columns): the explicit UFL ``frame``, else the
    material's constant (3, 3) ``frame``, else the identity.
    """
    if frame is not None:
        return frame
    R = getattr(p.material, "frame", None)
    if R is None:
        return ufl.Identity(3)
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (3, 3):
        return ufl.as_matrix(R.tolist()) if p.constant is None else p.wrap(R)
    raise ValueError(
        f"{type(p.material).__name__}: a per-cell frame of shape {R.shape} needs a mesh; pass "
        "frame= as a UFL expression (UFLOracle does this with a DG0 tensor Function)"
    )


def declared_energy(formula: Formula) -> EnergyFunction:
    """A declaration's formula (written against the formula namespace) as an EnergyFunction."""

    def energy(p: Parameters, F, frame) -> ufl.core.expr.Expr:
        return formula(p, UFLNamespace(F, _frame(p, frame)))

    return energy


def _register_declared() -> None:
    """Register the energy of every declared material (a fibre frame if it has the field)."""
    for declaration in declarations():
        takes_frame = any(f.name == "frame" for f in dataclasses.fields(declaration.material))
        energy = declared_energy(declaration.energy)
        register_energy(declaration.material, takes_frame=takes_frame)(energy)


_register_declared()


@register_energy(UserEnergy, takes_frame=True)
def _user_energy(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    # The user's expression, translated into UFL by its own parser (reference_fem/user_energy.py);
    # a per-cell frame (its first column is the fibre of I4 and I5) comes from the oracle.
    return p.material.ufl_density(F, constant=p.constant, frame=frame)
