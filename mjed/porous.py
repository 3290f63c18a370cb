"""The porous volumetric term of the liver model (paper, section 3.2).

The liver is a fluid-filled sponge whose rest volume is a fraction f_w of free fluid. Only the
solid fraction 1 - f_w resists compression, through the effective Jacobian

    J* = (f_w + J - 1) / f_w,

and a Hencky volumetric Cauchy stress  sigma(J) = K0 f_w ln J*, which tends to -infinity as
J -> 1 - f_w (the solid phase fully compacted). Below J0 the curve is replaced by its tangent
line at J0, so the stress stays finite and its slope stays bounded:

    sigma(J) = sigma(J0) + sigma'(J0) (J - J0)    for J <= J0.

Where the tangent is taken (``tangent``):

* ``"paper"`` (default): J0 = 1 - f_w + K0 / K_lim, the paper's formula. There the slope is
  sigma'(J0) = K0 f_w / (f_w + J0 - 1) = f_w K_lim, *not* K_lim: the paper's text calls K_lim
  "the slope of the tangent", which holds only for f_w = 1.
* ``"slope"``: J0 = 1 - f_w + f_w K0 / K_lim, the point where sigma'(J0) = K_lim exactly.

As an energy. For a volumetric energy U(J) per unit rest volume, the first Piola stress is
U'(J) J F^-T, so the Cauchy stress is U'(J) Id: the Cauchy pressure is dU/dJ. Integrating
sigma from J = 1 (where it is zero) gives, above J0,

    U(J) = K0 f_w^2 (J* ln J* - J* + 1),

and below J0 the quadratic  U(J0) + sigma(J0) (J - J0) + sigma'(J0) (J - J0)^2 / 2.
U is C^2 (U'' = sigma' is continuous at J0), zero with zero stress at rest (J0 < 1 is
required for that). :class:`PorousVolume` is an MJED function of J (value, first and second
derivative per cell) that the engine consumes like JPower or LogPolynomial, so it can be
attached to any material with :func:`with_porous_volume`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal, Tuple

import numpy as np

from mjed.materials.base import Material, require_positive
from mjed.terms import JFunction, Term, TermGroup, Unity

__all__ = ["PorousVolume", "PorousMaterial", "PorousSolid", "with_porous_volume"]


@dataclass(frozen=True)
class PorousVolume(JFunction):
    """U(J): the porous volumetric energy per unit rest volume (see the module docstring).

    Args:
        f_w: rest fraction of free fluid, 0 < f_w <= 1.
        K0: bulk modulus of the Hencky law (Pa), > 0.
        K_lim: limit bulk modulus setting the substitution point (Pa), > 0.
        tangent: "paper" (J0 = 1 - f_w + K0/K_lim) or "slope" (the J0 where sigma' = K_lim).

    Raises:
        ValueError: a parameter out of range, or J0 >= 1 (the substitution would reach the rest
            state, which would then not be stress free).
    """

    f_w: float
    K0: float
    K_lim: float
    tangent: Literal["paper", "slope"] = "paper"

    def __post_init__(self):
        require_positive(self, "f_w", "K0", "K_lim")
        if self.f_w > 1.0:
            raise ValueError(
                f"PorousVolume: parameter f_w must be <= 1 (a volume fraction), got {self.f_w!r}"
            )
        if self.tangent not in ("paper", "slope"):
            raise ValueError(
                f"PorousVolume: parameter tangent must be 'paper' or 'slope', got {self.tangent!r}"
            )
        if not self.J0 < 1.0:
            raise ValueError(
                f"PorousVolume: the substitution point J0 = {self.J0:.6g} must be < 1 (rest must "
                f"be stress free); K0/K_lim = {self.K0 / self.K_lim:.6g} is too large for f_w = "
                f"{self.f_w!r}"
            )

    # ------------------------------------------------------------------ the substitution point
    @property
    def J0(self) -> float:
        """Where the Hencky curve is replaced by its tangent."""
        ratio = self.K0 / self.K_lim
        return 1.0 - self.f_w + (ratio if self.tangent == "paper" else self.f_w * ratio)

    @property
    def tangent_slope(self) -> float:
        """sigma'(J0) = K0 f_w / (f_w + J0 - 1): f_w K_lim for "paper", K_lim for "slope"."""
        return self.K0 * self.f_w / (self.f_w + self.J0 - 1.0)

    # ------------------------------------------------------------------ stresses
    def hencky_stress(self, J) -> np.ndarray:
        """Sigma = K0 f_w ln J* without substitution (NaN-free only for J > 1 - f_w)."""
        J = np.asarray(J, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.K0 * self.f_w * np.log((self.f_w + J - 1.0) / self.f_w)

    def stress(self, J) -> np.ndarray:
        """The substituted volumetric Cauchy stress dU/dJ (Pa), same shape as J."""
        return self(np.asarray(J, dtype=float))[1]

    # ------------------------------------------------------------------ the energy
    def __call__(self, J) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """U(J), U'(J) = sigma, U''(J), each shaped like J."""
        J = np.asarray(J, dtype=float)
        fw, K0, J0 = self.f_w, self.K0, self.J0
        above = J > J0
        # The log branch is evaluated on J clipped to the valid side, then masked: no NaN leaks.
        Js = (fw + np.where(above, J, J0) - 1.0) / fw
        L = np.log(Js)
        U_log = K0 * fw * fw * (Js * L - Js + 1.0)
        s_log = K0 * fw * L
        k_log = K0 * fw / (fw + np.where(above, J, J0) - 1.0)

        Js0 = (fw + J0 - 1.0) / fw
        L0 = np.log(Js0)
        U0 = K0 * fw * fw * (Js0 * L0 - Js0 + 1.0)
        s0 = K0 * fw * L0
        k0 = self.tangent_slope
        d = J - J0
        U_lin = U0 + s0 * d + 0.5 * k0 * d * d
        s_lin = s0 + k0 * d
        return (
            np.where(above, U_log, U_lin),
            np.where(above, s_log, s_lin),
            np.where(above, k_log, k0),
        )


@dataclass(frozen=True)
class PorousMaterial(Material):
    """A material with the porous volumetric energy U(J) attached (see :func:`with_porous_volume`).

    W = W_base + U(J) for mode "add"; W = W_base without its volumetric part + U(J) for
    mode "replace".
    """

    base: Material
    porous: PorousVolume
    mode: Literal["add", "replace"] = "add"

    def __post_init__(self):
        if not isinstance(self.base, Material):
            raise ValueError(
                "PorousMaterial: parameter base must be an mjed material, got "
                f"{type(self.base).__name__}"
            )
        if isinstance(self.base, PorousMaterial):
            raise ValueError("PorousMaterial: parameter base already has a porous volume")
        if not isinstance(self.porous, PorousVolume):
            raise ValueError(
                "PorousMaterial: parameter porous must be a PorousVolume, got "
                f"{type(self.porous).__name__}"
            )
        if self.mode not in ("add", "replace"):
            raise ValueError(
                f"PorousMaterial: parameter mode must be 'add' or 'replace', got {self.mode!r}"
            )
        self.decomposition()  # a material whose volumetric part cannot be replaced fails here

    @property
    def name(self) -> str:
        return f"Porous{self.base.name}"

    def decomposition(self) -> Tuple[TermGroup, ...]:
        groups = self.base.decomposition()
        if self.mode == "replace":
            groups = tuple(_without_volumetric(g, self.base.name) for g in groups)
        return groups + (TermGroup((Term(self.porous, Unity()),)),)


@dataclass(frozen=True)
class PorousSolid(Material):
    """The porous volumetric energy U(J) alone, as a material: the porous network of Kerdok's
    parallel networks, to be given its own force field next to the hyperelastic (or
    visco-hyperelastic) one, so that a Prony series on the latter does not relax it.
    """

    porous: PorousVolume

    def __post_init__(self):
        if not isinstance(self.porous, PorousVolume):
            raise ValueError(
                "PorousSolid: parameter porous must be a PorousVolume, got "
                f"{type(self.porous).__name__}"
            )

    def decomposition(self) -> Tuple[TermGroup, ...]:
        return (TermGroup((Term(self.porous, Unity()),)),)


@dataclass(frozen=True)
class _Constant(JFunction):
    """f = c: what remains of a replaced volumetric term (its value at rest)."""

    c: float

    def __call__(self, J):
        return self.c, 0.0, 0.0


def _without_volumetric(group: TermGroup, material: str) -> TermGroup:
    """The group with each pure function of J (g = 1) replaced by its rest value.

    Keeping f(1) keeps the energy zero at rest. A J-only term with f'(1) != 0 carries part of
    the response that balances the isochoric stress at rest (NeoHookean's -mu ln J); removing
    it would leave the rest state stressed, so it is refused.
    """
    terms = []
    for term in group.terms:
        if not isinstance(term.g, Unity):
            terms.append(term)
            continue
        if not group.plain:
            raise ValueError(
                f"with_porous_volume: {material} has a J-only term inside a group with a function "
                "of its sum (exp, log, power); use mode='add'"
            )
        f1, df1, _ = term.f(np.ones(1))
        if abs(float(np.asarray(df1).ravel()[0])) > 0.0:
            raise ValueError(
                f"with_porous_volume: {material}'s J-only term has a non-zero slope at J = 1 (it "
                "balances the isochoric stress at rest), so it cannot be replaced; use mode='add'"
            )
        terms.append(Term(_Constant(float(np.asarray(f1).ravel()[0])), Unity()))
    return dataclasses.replace(group, terms=tuple(terms))


def with_porous_volume(
    material: Material, porous: PorousVolume, *, mode: Literal["add", "replace"] = "add"
) -> PorousMaterial:
    """``material`` with the porous volumetric energy U(J).

    mode "add" (default, the paper's liver: Kerdok's parallel hyperelastic and porous
    networks) keeps the material's own volumetric term (k0) and adds U. mode "replace" drops
    the material's J-only terms (its k0 part) so that U alone controls the volume; it is
    refused (ValueError) for materials without such a term or whose J-only term is not
    stationary at rest (NeoHookean).
    """
    if mode == "replace":
        has_volumetric = any(
            isinstance(t.g, Unity) for g in material.decomposition() for t in g.terms
        )
        if not has_volumetric:
            raise ValueError(
                f"with_porous_volume: {material.name} has no J-only (volumetric) term to replace; "
                "use mode='add'"
            )
    return PorousMaterial(material, porous, mode)
