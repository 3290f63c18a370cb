"""Strain energy densities W(F) written directly in UFL, one function per material.

This module is the "oracle" side of the verification: every energy is typed in from its
formula in the project conventions (CONVENTIONS.md, "Strain energies W") and nothing else.
It never imports the MJED term code; it only reads a material's *parameters* (attributes
of the frozen dataclasses in ``mjed.materials``), dispatching on the class name so that any
object with the right name and fields works (the tests use stand-ins).

Each function follows the same layout: parameters, kinematics from F, then psi. ``F`` is a
UFL 3x3 expression (F = I + grad u); the result is a scalar UFL expression, per unit rest
volume. Parameters enter as plain numbers by default, or through a ``constant`` factory
(the oracle makes dolfinx Constants): then the compiled forms do not depend on the parameter
values and FFCx compiles each material type once, not once per parameter set.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Dict, NamedTuple, Optional

import numpy as np
import ufl

from reference_fem.ogden_eigen import sum_of_eigenvalue_powers

__all__ = ["strain_energy_density", "supported_materials", "ARRUDA_BOYCE_COEFFICIENTS"]

# 8-chain series coefficients c_1..c_5 of the Arruda-Boyce energy.
ARRUDA_BOYCE_COEFFICIENTS = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


class _Params:
    """A material's parameters, read by name: ``p.value(name)`` as a float (for checks),
    ``p(name)`` as it enters the formula (a number, or what ``constant`` makes of it)."""

    def __init__(self, material: Any, constant: Optional[Callable[[Any], Any]]):
        self.material = material
        self.constant = constant

    def value(self, name: str) -> float:
        m = self.material
        if not hasattr(m, name):
            raise ValueError(f"{type(m).__name__}: missing parameter {name!r}")
        try:
            v = float(getattr(m, name))
        except (TypeError, ValueError):
            got = getattr(m, name)
            msg = f"{type(m).__name__}: parameter {name} must be a real number, got {got!r}"
            raise ValueError(msg) from None
        if not math.isfinite(v):
            raise ValueError(f"{type(m).__name__}: parameter {name} must be finite, got {v!r}")
        return v

    def wrap(self, value):
        return value if self.constant is None else self.constant(value)

    def __call__(self, name: str):
        return self.wrap(self.value(name))


class _Kinematics(NamedTuple):
    """The quantities every formula is written in (CONVENTIONS.md, "Kinematics")."""

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


def _stvk(p: _Params, F, frame) -> ufl.core.expr.Expr:
    mu, lam = p("mu"), p("lam")
    E = _kinematics(F).E
    return 0.5 * lam * ufl.tr(E) ** 2 + mu * ufl.tr(E * E)


def _neo_hookean(p: _Params, F, frame) -> ufl.core.expr.Expr:
    mu, lam = p("mu"), p("lam")
    k = _kinematics(F)
    return 0.5 * mu * (k.I1 - 3.0) - mu * k.lnJ + 0.5 * lam * k.lnJ ** 2


def _mooney_rivlin(p: _Params, F, frame) -> ufl.core.expr.Expr:
    c1, c2, k0 = p("c1"), p("c2"), p("k0")
    k = _kinematics(F)
    return c1 * (k.I1b - 3.0) + c2 * (k.I2b - 3.0) + 0.5 * k0 * k.lnJ ** 2


def _veronda_westmann(p: _Params, F, frame) -> ufl.core.expr.Expr:
    c1, c2, k0 = p("c1"), p("c2"), p("k0")
    k = _kinematics(F)
    return (
        c1 * (ufl.exp(c2 * (k.I1b - 3.0)) - 1.0)
        - 0.5 * c1 * c2 * (k.I2b - 3.0)
        + 0.5 * k0 * k.lnJ ** 2
    )


def _arruda_boyce(p: _Params, F, frame) -> ufl.core.expr.Expr:
    mu, k0 = p("mu"), p("k0")
    N = p("N") if hasattr(p.material, "N") else p.wrap(8.0)
    k = _kinematics(F)
    series = sum(
        c * N ** (1 - i) * (k.I1b ** i - 3.0**i)
        for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)
    )
    return mu * series + 0.5 * k0 * k.lnJ ** 2


def _costa_frame(p: _Params, frame) -> ufl.core.expr.Expr:
    """The fibre/sheet/normal frame R (columns): the explicit UFL ``frame``, else the
    material's constant (3, 3) ``frame``, else the identity."""
    if frame is not None:
        return frame
    R = getattr(p.material, "frame", None)
    if R is None:
        return ufl.Identity(3)
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (3, 3):
        return ufl.as_matrix(R.tolist()) if p.constant is None else p.wrap(R)
    raise ValueError(
        f"Costa: a per-cell frame of shape {R.shape} needs a mesh; pass frame= as a UFL "
        "expression (UFLOracle does this with a DG0 tensor Function)"
    )


def _costa(p: _Params, F, frame) -> ufl.core.expr.Expr:
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


def _ogden(p: _Params, F, frame) -> ufl.core.expr.Expr:
    if p.value("alpha") == 0.0:
        raise ValueError("Ogden: parameter alpha must be non-zero")
    mu, alpha, k0 = p("mu"), p("alpha"), p("k0")
    k = _kinematics(F)
    # sum_i lambda_i^(alpha/2) over the eigenvalues lambda_i of C (= principal stretches^alpha).
    stretch_sum = sum_of_eigenvalue_powers(k.C, 0.5 * alpha)
    return mu / alpha**2 * (k.J ** (-alpha / 3.0) * stretch_sum - 3.0) + 0.5 * k0 * k.lnJ ** 2


_DISPATCH: Dict[str, Callable[[_Params, Any, Any], ufl.core.expr.Expr]] = {
    "StVenantKirchhoff": _stvk,
    "NeoHookean": _neo_hookean,
    "MooneyRivlin": _mooney_rivlin,
    "VerondaWestmann": _veronda_westmann,
    "ArrudaBoyce": _arruda_boyce,
    "Costa": _costa,
    "Ogden": _ogden,
}


def supported_materials() -> tuple:
    """Names of the material classes the oracle knows, e.g. ``("StVenantKirchhoff", ...)``."""
    return tuple(_DISPATCH)


def strain_energy_density(
    material: Any,
    F: ufl.core.expr.Expr,
    *,
    frame: Optional[Any] = None,
    constant: Optional[Callable[[Any], Any]] = None,
) -> ufl.core.expr.Expr:
    """W(F) per unit rest volume, as a scalar UFL expression.

    Args:
        material: an object whose class name is one of :func:`supported_materials` and
            whose attributes are that material's parameters (``mjed.materials`` dataclasses).
        F: the deformation gradient, a UFL 3x3 expression.
        frame: Costa only: a UFL 3x3 rotation (columns fibre, sheet, normal) overriding the
            material's ``frame``; needed when the material holds one rotation per cell.

    Raises:
        ValueError: unknown material class, missing or non-finite parameter.
    """
    name = type(material).__name__
    try:
        energy = _DISPATCH[name]
    except KeyError:
        raise ValueError(
            f"no UFL energy for material class {name!r}; known: {', '.join(_DISPATCH)}"
        ) from None
    if frame is not None and name != "Costa":
        raise ValueError(f"frame= is only meaningful for Costa, not {name}")
    return energy(_Params(material, constant), F, frame)
