"""Closed-form homogeneous uniaxial stress, and the reaction MJED gives on a cube.

The analytic side is written in principal stretches, by hand, for the compressible energies of
docs/conventions.md (nothing here calls mjed's terms). For a decoupled energy
W = W_iso(I1b, I2b) + U(J) the principal Cauchy stresses are

    sigma_i = (2/J) [(W1 + I1b W2) b_i - W2 b_i^2 - (W1 I1b + 2 W2 I2b)/3] + U'(J),

with b_i = J^(-2/3) lambda_i^2 the principal values of the isochoric left Cauchy-Green tensor
and W1, W2 the derivatives of W_iso. Neo-Hookean, St Venant-Kirchhoff and Ogden are not of
that form and get their own lines. A material with no lines of its own whose declaration gives
the decoupled classical form (mjed.materials.classical_forms.Decoupled, e.g. Yeoh, Gent) uses
that form's W1, W2 and k0/2 (ln J)^2, so a new material of that form needs nothing here.
Uniaxial stress means sigma_2 = sigma_3 = 0: the lateral stretch is the root of
sigma_2(lambda, t, t) = 0.

The discrete side prescribes x = F X on every node of a cube mesh. For a homogeneous F the
nodal forces of interior nodes vanish and the forces on the face X = max add up to the first
Piola-Kirchhoff traction times the rest area, so the loaded face's reaction divided by the
current area must equal sigma_11, and the lateral faces must carry no normal reaction.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from typing import Tuple

import numpy as np
from scipy.optimize import brentq

from mjed.materials import (
    ArrudaBoyce,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    StVenantKirchhoff,
    VerondaWestmann,
    declarations,
)
from mjed.materials.arruda_boyce import ARRUDA_BOYCE_COEFFICIENTS
from mjed.materials.classical_forms import Decoupled
from mjed.materials.declaration import declaration_of

__all__ = [
    "ISOTROPIC",
    "has_closed_form",
    "principal_cauchy",
    "uniaxial_lateral_stretch",
    "uniaxial_cauchy",
    "UniaxialResult",
    "uniaxial_reaction_check",
    "UNIAXIAL_STRETCHES",
    "uniaxial_checks",
]

#: The stretches of the uniaxial check: one in tension, one in compression.
UNIAXIAL_STRETCHES = (1.3, 0.8)

Stretches = Tuple[float, float, float]


def _decoupled(W1: float, W2: float, Up: float, stretches: Stretches) -> np.ndarray:
    lam = np.asarray(stretches, dtype=float)
    J = float(np.prod(lam))
    b = J ** (-2.0 / 3.0) * lam**2
    I1b = b.sum()
    I2b = b[0] * b[1] + b[1] * b[2] + b[0] * b[2]
    return 2.0 / J * ((W1 + I1b * W2) * b - W2 * b**2 - (W1 * I1b + 2.0 * W2 * I2b) / 3.0) + Up


def _isochoric_I1(stretches: Stretches) -> float:
    lam = np.asarray(stretches, dtype=float)
    return float(np.prod(lam) ** (-2.0 / 3.0) * (lam**2).sum())


def _decoupled_form(material) -> "Decoupled | None":
    """The declared classical form of ``material`` when it is the decoupled one, else None."""
    try:
        form = declaration_of(type(material)).classical(material)
    except (LookupError, TypeError):  # not a declared material
        return None
    return form if isinstance(form, Decoupled) else None


class _Named:
    """The parameters of a decoupled form, read by attribute as its Psi reads them."""

    def __init__(self, pairs):
        self.__dict__.update({name: float(value) for name, value in pairs})


@functools.singledispatch
def _principal(material, s: Stretches) -> np.ndarray:
    """Principal Cauchy stresses (3,) of ``material`` under F = diag(s), dispatched on its type;
    without lines of its own, a declared decoupled form's Psi derivatives.
    """
    form = _decoupled_form(material)
    if form is not None:
        J = float(np.prod(s))
        lam = np.asarray(s, dtype=float)
        b = J ** (-2.0 / 3.0) * lam**2
        I2b = b[0] * b[1] + b[1] * b[2] + b[0] * b[2]
        with np.errstate(invalid="ignore", divide="ignore"):  # Psi itself may be undefined (Gent
            # far beyond its lock, tried while bracketing the lateral stretch); W1, W2 are not
            _, W1, W2, *_ = form.psi.function(_Named(form.parameters), b.sum(), I2b, np)
        return _decoupled(float(W1), float(W2), form.k0 * np.log(J) / J, s)
    cls = type(material)
    raise ValueError(
        f"no closed form for {cls.__qualname__}; isotropic materials with one: "
        f"{', '.join(t.__qualname__ for t in ISOTROPIC)}"
    )


@_principal.register
def _stvk(m: StVenantKirchhoff, s: Stretches) -> np.ndarray:
    lam = np.asarray(s, dtype=float)
    E = (lam**2 - 1.0) / 2.0
    S = m.lam * E.sum() + 2.0 * m.mu * E
    return lam**2 * S / np.prod(lam)


@_principal.register
def _neo_hookean(m: NeoHookean, s: Stretches) -> np.ndarray:
    lam = np.asarray(s, dtype=float)
    J = np.prod(lam)
    return (m.mu * (lam**2 - 1.0) + m.lam * np.log(J)) / J


@_principal.register
def _mooney_rivlin(m: MooneyRivlin, s: Stretches) -> np.ndarray:
    J = float(np.prod(s))
    return _decoupled(m.c1, m.c2, m.k0 * np.log(J) / J, s)


@_principal.register
def _veronda_westmann(m: VerondaWestmann, s: Stretches) -> np.ndarray:
    J = float(np.prod(s))
    W1 = m.c1 * m.c2 * np.exp(m.c2 * (_isochoric_I1(s) - 3.0))
    return _decoupled(W1, -m.c1 * m.c2 / 2.0, m.k0 * np.log(J) / J, s)


@_principal.register
def _arruda_boyce(m: ArrudaBoyce, s: Stretches) -> np.ndarray:
    J = float(np.prod(s))
    I1b = _isochoric_I1(s)
    W1 = m.mu * sum(
        i * c * m.N ** (1 - i) * I1b ** (i - 1)
        for i, c in enumerate(ARRUDA_BOYCE_COEFFICIENTS, start=1)
    )
    return _decoupled(W1, 0.0, m.k0 * np.log(J) / J, s)


@_principal.register
def _ogden(m: Ogden, s: Stretches) -> np.ndarray:
    # W = mu/alpha^2 (sum lb_i^alpha - 3) + k0/2 ln^2 J with lb_i = J^(-1/3) lambda_i;
    # sigma_i = (lambda_i / J) dW/dlambda_i.
    lam = np.asarray(s, dtype=float)
    J = np.prod(lam)
    p = (J ** (-1.0 / 3.0) * lam) ** m.alpha
    return (m.mu / m.alpha * (p - p.mean()) + m.k0 * np.log(J)) / J


#: The isotropic material types with a closed form: their own lines, then the declared ones of
#: the decoupled form.
ISOTROPIC: Tuple[type, ...] = tuple(t for t in _principal.registry if t is not object) + tuple(
    d.material
    for d in declarations()
    if d.material not in _principal.registry and isinstance(d.classical(d.default), Decoupled)
)


def has_closed_form(material) -> bool:
    """True when the material's type (or a base of it) has a closed form here."""
    if _principal.dispatch(type(material)) is not _principal.dispatch(object):
        return True
    return _decoupled_form(material) is not None


def principal_cauchy(material, stretches: Stretches) -> np.ndarray:
    """Principal Cauchy stresses (3,) of an isotropic material under F = diag(stretches)."""
    if not all(np.isfinite(stretches)) or min(stretches) <= 0:
        raise ValueError(f"stretches must be finite and positive, got {tuple(stretches)}")
    return _principal(material, tuple(float(v) for v in stretches))


def uniaxial_lateral_stretch(material, stretch: float) -> float:
    """The lateral stretch t making sigma_2 = sigma_3 = 0 under F = diag(stretch, t, t)."""
    lateral = lambda t: principal_cauchy(material, (stretch, t, t))[1]
    lo, hi = 0.2, 3.0
    if not lateral(lo) < 0.0 < lateral(hi):
        raise ValueError(
            f"{type(material).__name__}: no lateral stretch in ({lo}, {hi}) frees the sides at "
            f"stretch {stretch}"
        )
    return float(brentq(lateral, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200))


def uniaxial_cauchy(material, stretch: float) -> Tuple[float, float]:
    """(sigma_11, lateral stretch) in homogeneous uniaxial stress."""
    t = uniaxial_lateral_stretch(material, stretch)
    return float(principal_cauchy(material, (stretch, t, t))[0]), t


@dataclass
class UniaxialResult:
    material: str
    stretch: float
    lateral_stretch: float
    sigma_analytic: float
    sigma_mjed: float
    rel_err: float
    lateral_reaction_rel: float

    def to_dict(self) -> dict:
        return asdict(self)


def uniaxial_reaction_check(
    material, points: np.ndarray, cells: np.ndarray, stretch: float
) -> UniaxialResult:
    """Cube stretched along x in uniaxial stress: MJED's face reaction against sigma_11.

    points (n, 3) of an axis-aligned box mesh; cells (m, 4).
    """
    import mjed

    sigma, t = uniaxial_cauchy(material, stretch)
    points = np.asarray(points, dtype=float)
    lo, hi = points.min(axis=0), points.max(axis=0)
    size = hi - lo
    x = lo + (points - lo) * np.array([stretch, t, t])
    force = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material).force(x)
    tol = 1e-9 * size.max()
    # The force a support must apply to hold each face is +dW/dx = -f.
    reaction = [(-force[np.abs(points[:, k] - hi[k]) < tol, k]).sum() for k in range(3)]
    current_area = lambda k: np.prod(np.delete(size * np.array([stretch, t, t]), k))
    sigma_mjed = reaction[0] / current_area(0)
    scale = max(abs(sigma), 1e-300)
    lateral = max(abs(reaction[1]) / current_area(1), abs(reaction[2]) / current_area(2)) / scale
    return UniaxialResult(
        material=material.name,
        stretch=float(stretch),
        lateral_stretch=t,
        sigma_analytic=sigma,
        sigma_mjed=float(sigma_mjed),
        rel_err=float(abs(sigma_mjed - sigma) / scale),
        lateral_reaction_rel=float(lateral),
    )


def uniaxial_checks(materials, label: str, points: np.ndarray, cells: np.ndarray) -> list:
    """The face-reaction check of every isotropic material at UNIAXIAL_STRETCHES on one box mesh.

    Returns one dict per (material, stretch): UniaxialResult's fields plus ``mesh`` and
    ``passed`` (both errors within the equivalence suite's force tolerance). Materials
    without a closed form (Costa) are skipped.
    """
    from common.tolerances import FORCE_TOL

    rows = []
    for m in materials:
        if not has_closed_form(m):
            continue
        for stretch in UNIAXIAL_STRETCHES:
            r = uniaxial_reaction_check(m, points, cells, stretch).to_dict()
            r.update(
                mesh=label,
                passed=bool(r["rel_err"] <= FORCE_TOL and r["lateral_reaction_rel"] <= FORCE_TOL),
            )
            rows.append(r)
    return rows
