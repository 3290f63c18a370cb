"""Strain energy densities W(F) written directly in UFL, one function per material type.

This module is the "oracle" side of the verification: every energy is typed in from its
formula in docs/conventions.md and nothing else. It never imports the MJED term code
(mjed.terms, mjed.engine, mjed.fibre, mjed.spectral); it reads a material's *parameters*
(attributes of the frozen dataclasses in ``mjed.materials``) and the constants that are part
of a material's definition (the Arruda-Boyce series coefficients).

Dispatch is on the material's type through a public registry: :func:`register_energy`
declares the UFL energy of a type (subclasses inherit it), :func:`energy_formula` finds it,
and :func:`strain_energy_density` builds the expression. Adding a material means one
``@register_energy(MyMaterial)`` function here; another module may register its own types
the same way (e.g. a user-written energy), without editing this file::

    from reference_fem.energies import register_energy

    @register_energy(MyMaterial)
    def _my_energy(p, F, frame):
        mu = p("mu")                      # a parameter, as it enters the formula
        return 0.5 * mu * (ufl.tr(F.T * F) - 3.0)

Each function follows the same layout: parameters, kinematics from F, then psi. ``F`` is a
UFL 3x3 expression (F = I + grad u); the result is a scalar UFL expression, per unit rest
volume. Parameters enter as plain numbers by default, or through a ``constant`` factory
(the oracle makes dolfinx Constants): then the compiled forms do not depend on the parameter
values and FFCx compiles each material type once, not once per parameter set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, Mapping, NamedTuple, Optional, Tuple

import numpy as np
import ufl

from mjed.materials import (
    ArrudaBoyce,
    Costa,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    StVenantKirchhoff,
    VerondaWestmann,
)
from mjed.materials.isotropic import ARRUDA_BOYCE_COEFFICIENTS
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


class _Kinematics(NamedTuple):
    """The quantities every formula is written in (docs/conventions.md, "Kinematics")."""

    C: Any  # right Cauchy-Green tensor F^T F
    E: Any  # Green-Lagrange strain (C - I) / 2
    I1: Any
    I2: Any
    J: Any
    lnJ: Any
    I1b: Any  # J^(-2/3) I1
    I2b: Any  # J^(-4/3) I2


def _kinematics(F: ufl.core.expr.Expr) -> _Kinematics:
    C = F.T * F
    I1 = ufl.tr(C)
    J = ufl.det(F)
    I2 = 0.5 * (I1**2 - ufl.tr(C * C))
    return _Kinematics(
        C=C,
        E=0.5 * (C - ufl.Identity(3)),
        I1=I1,
        I2=I2,
        J=J,
        lnJ=ufl.ln(J),
        I1b=J ** (-2.0 / 3.0) * I1,
        I2b=J ** (-4.0 / 3.0) * I2,
    )


@register_energy(StVenantKirchhoff)
def _stvk(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    mu, lam = p("mu"), p("lam")
    E = _kinematics(F).E
    return 0.5 * lam * ufl.tr(E) ** 2 + mu * ufl.tr(E * E)


@register_energy(NeoHookean)
def _neo_hookean(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    mu, lam = p("mu"), p("lam")
    k = _kinematics(F)
    return 0.5 * mu * (k.I1 - 3.0) - mu * k.lnJ + 0.5 * lam * k.lnJ**2


@register_energy(MooneyRivlin)
def _mooney_rivlin(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    c1, c2, k0 = p("c1"), p("c2"), p("k0")
    k = _kinematics(F)
    return c1 * (k.I1b - 3.0) + c2 * (k.I2b - 3.0) + 0.5 * k0 * k.lnJ**2


@register_energy(VerondaWestmann)
def _veronda_westmann(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    c1, c2, k0 = p("c1"), p("c2"), p("k0")
    k = _kinematics(F)
    return (
        c1 * (ufl.exp(c2 * (k.I1b - 3.0)) - 1.0)
        - 0.5 * c1 * c2 * (k.I2b - 3.0)
        + 0.5 * k0 * k.lnJ**2
    )


@register_energy(ArrudaBoyce)
def _arruda_boyce(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    mu, k0 = p("mu"), p("k0")
    N = p("N")
    k = _kinematics(F)
    series = sum(
        c * N ** (1 - i) * (k.I1b**i - 3.0**i)
        for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)
    )
    return mu * series + 0.5 * k0 * k.lnJ**2


def _costa_frame(p: Parameters, frame) -> ufl.core.expr.Expr:
    """The fibre/sheet/normal frame R (columns): the explicit UFL ``frame``, else the
    material's constant (3, 3) ``frame``, else the identity.
    """
    if frame is not None:
        return frame
    R = p.material.frame
    if R is None:
        return ufl.Identity(3)
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (3, 3):
        return ufl.as_matrix(R.tolist()) if p.constant is None else p.wrap(R)
    raise ValueError(
        f"Costa: a per-cell frame of shape {R.shape} needs a mesh; pass frame= as a UFL expression "
        "(UFLOracle does this with a DG0 tensor Function)"
    )


@register_energy(Costa, takes_frame=True)
def _costa(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    a, k0 = p("a"), p("k0")
    b = {n: p(n) for n in ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")}
    B = [
        [b["b_ff"], b["b_fs"], b["b_fn"]],
        [b["b_fs"], b["b_ss"], b["b_sn"]],
        [b["b_fn"], b["b_sn"], b["b_nn"]],
    ]
    k = _kinematics(F)
    R = _costa_frame(p, frame)
    Ef = R.T * k.E * R  # strain in the fibre frame
    Q = sum(B[i][j] * Ef[i, j] ** 2 for i in range(3) for j in range(3))
    return 0.5 * a * (ufl.exp(k.J ** (-4.0 / 3.0) * Q) - 1.0) + k0 * (k.J * k.lnJ - k.J + 1.0)


@register_energy(Ogden)
def _ogden(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    if p.value("alpha") == 0.0:
        raise ValueError("Ogden: parameter alpha must be non-zero")
    mu, alpha, k0 = p("mu"), p("alpha"), p("k0")
    k = _kinematics(F)
    # sum_i lambda_i^(alpha/2) over the eigenvalues lambda_i of C (= principal stretches^alpha).
    stretch_sum = sum_of_eigenvalue_powers(k.C, 0.5 * alpha)
    return mu / alpha**2 * (k.J ** (-alpha / 3.0) * stretch_sum - 3.0) + 0.5 * k0 * k.lnJ**2


@register_energy(UserEnergy, takes_frame=True)
def _user_energy(p: Parameters, F, frame) -> ufl.core.expr.Expr:
    # The user's expression, translated into UFL by its own parser (reference_fem/user_energy.py);
    # a per-cell frame (its first column is the fibre of I4 and I5) comes from the oracle.
    return p.material.ufl_density(F, constant=p.constant, frame=frame)
