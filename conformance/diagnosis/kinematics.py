"""Kinematic mistakes as oracle variants, for every material with a formula (Ogden and Costa
included) and every user energy.

The energy is evaluated as an engine that gets its kinematics wrong would
(:class:`conformance.diagnosis.energy_terms.Spec`); the oracle differentiates each variant, and
the engine is said to match one when its force and stiffness agree with that variant within the
case's tolerance. The mistakes:

- C and B confused (F^T used for F): identical for an isotropic energy, so tried only where the
  energy reads a fibre frame;
- the deformation gradient of the inverse map, F^-1 for F (dX/dx, as an updated-Lagrangian code
  holds it, for dx/dX), and its symmetric part (F + F^T)/2 for F (the rotation ignored: F taken
  for its stretch U, exact while the cells do not rotate);
- the displacements taken as rest minus current, u = X - x (F = I - grad u = 2 I - F for F):
  the energy, stress and tangent of the reversed deformation, the force's sign flipped by the
  chain rule (the engine's f = -dW/du' at u' = -u is minus the variant's -dW/du);
- the off-diagonal entries of C lost (the energy of diag C: an eigen-solver that reads the
  empty triangle of a C stored in one, or the shear strains dropped);
- the energy weighted by the deformed volume (J W for W);
- principal stretches confused with their squares (the power of the eigenvalues of C doubled or
  halved, I1 taken as tr(C^2) or as the sum of the stretches);
- the strain measure: E = C - I (Green's 1/2 dropped), the linearised strain (F + F^T)/2 - I
  or the isochoric (J^(-2/3) C - I)/2 for E = (C - I)/2 (formulas written in E: St
  Venant-Kirchhoff, Costa, a user energy's Eij);
- the isochoric power of J (every non-integer power of J, or each one alone, multiplied by 0,
  1/2, 2 or -1: its minus sign lost);
- a power of J that multiplies an exponential's argument applied to the whole exponential
  term instead (c (exp(J^p X) - 1) as c J^p (exp(X) - 1));
- the fibre frame in the deformed configuration (F R, normalised, for R), or pushed forward and
  re-orthonormalised (Gram-Schmidt) as an engine keeping the frame orthonormal would.

A variant that is the same formula as the energy itself (a mistake the energy cannot show, e.g.
no eigenvalues in it) is not evaluated.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, List, Tuple

import numpy as np

from conformance.diagnosis.energy_terms import Spec, has_formula, j_power_exponents

__all__ = ["KinematicVariant", "OrthonormalisedFrameEnergy", "kinematic_variants"]


@dataclass(frozen=True)
class KinematicVariant:
    """code, title (the mistake in words), spec (how the oracle evaluates it); force_sign: the
    engine's force is this times the variant's (-1 where the engine differentiates in
    displacements that are the variant's negated).
    """

    code: str
    title: str
    spec: Spec
    orthonormalised: bool = False
    force_sign: float = 1.0

    def oracle_model(self, model: Any) -> Any:
        """What the oracle evaluates for this variant of ``model``."""
        from conformance.diagnosis.transformed import TransformedEnergy

        if self.orthonormalised:
            return OrthonormalisedFrameEnergy(model)
        return TransformedEnergy(model, self.spec)

    def key(self) -> str:
        return self.spec.key() + (" orthonormalised" if self.orthonormalised else "")


@dataclass(frozen=True, eq=False)
class OrthonormalisedFrameEnergy:
    """``model``'s energy with its fibre frame pushed forward and re-orthonormalised (Gram-
    Schmidt: fibre F R e_f normalised, sheet F R e_s made orthogonal to it and normalised,
    normal their cross product): a material for the oracle.
    """

    model: Any

    @property
    def frame(self):
        return getattr(self.model, "frame", None)


def _register() -> None:
    from reference_fem.energies import register_energy, supported_materials

    if OrthonormalisedFrameEnergy in supported_materials():
        return

    @register_energy(OrthonormalisedFrameEnergy, takes_frame=True)
    def _energy(p, F, frame):
        import ufl

        from conformance.diagnosis.energy_terms import build

        R = frame
        if R is not None:
            FR = F * R
            f = FR[:, 0] / ufl.sqrt(ufl.dot(FR[:, 0], FR[:, 0]))
            s = FR[:, 1] - ufl.dot(f, FR[:, 1]) * f
            s = s / ufl.sqrt(ufl.dot(s, s))
            n = ufl.cross(f, s)
            R = ufl.as_matrix([[f[i], s[i], n[i]] for i in range(3)])
        W, _ = build(p.material.model, F, R, p.constant, Spec())
        return W


_register()


_R_WORDS = {0.0: "left out (J^0)", 0.5: "halved", 2.0: "doubled", -1.0: "with its sign flipped"}


def _formula_text(model: Any, spec: Spec) -> str:
    """The variant's UFL expression printed (plain floats for parameters): to tell variants that
    change nothing.
    """
    from conformance.diagnosis.energy_terms import symbolic

    W, _, _ = symbolic(model, spec, _Symbols(model))
    # UFL numbers the free indices of each build anew: renumber them in order of appearance.
    seen: dict = {}
    return re.sub(
        r"i_\{?(\d+)\}?", lambda m: "i" + str(seen.setdefault(m.group(1), len(seen))), str(W)
    )


class _Symbols:
    """Parameters as UFL symbols, the same objects for every build of one model (the k-th
    parameter read is the k-th symbol), so that two builds print alike where they agree, and a
    power of J with a parameter in it (Ogden's J^(-alpha/3)) is never taken for an integer.
    """

    _pools: dict = {}

    def __init__(self, model: Any):
        self.pool = _Symbols._pools.setdefault(type(model).__name__, [])
        self.k = 0

    def __call__(self, v):
        import ufl

        from conformance.diagnosis.energy_terms import symbolic_domain

        shape = np.shape(v)
        while len(self.pool) <= self.k:
            self.pool.append({})
        slot = self.pool[self.k]
        if shape not in slot:
            slot[shape] = ufl.Constant(symbolic_domain(), shape=shape)
        self.k += 1
        return slot[shape]


def _uses_frame(model: Any) -> bool:
    from reference_fem.user_energy import UserEnergy

    if isinstance(model, UserEnergy):
        return bool(model.uses_fibre)
    return getattr(model, "frame", None) is not None or "frame" in getattr(
        type(model), "__dataclass_fields__", {}
    )


def kinematic_variants(model: Any) -> List[KinematicVariant]:
    """The kinematic variants of ``model`` that change its energy (empty without a formula)."""
    if not has_formula(model):
        return []
    try:
        base = _formula_text(model, Spec())
    except Exception:  # noqa: BLE001 - a formula this module cannot rewrite: no variants
        return []
    out: List[Tuple[str, str, Spec]] = []
    if _uses_frame(model):
        out.append(
            (
                "C-B-confused",
                "C and B confused: F^T used for F (B = F F^T where C = F^T F belongs)",
                Spec(transpose=True),
            )
        )
        out.append(
            (
                "frame-deformed",
                "the fibre frame taken in the deformed configuration: F R (normalised) for R",
                Spec(frame_deformed=True),
            )
        )
    out += [
        (
            "inverse-map",
            "the deformation gradient of the inverse map: F^-1 (dX/dx, from the current cell to "
            "the rest one) used for F = dx/dX",
            Spec(deformation="inverse"),
        ),
        (
            "displacement-reversed",
            "the displacements taken as rest minus current, u = X - x (F = I - grad u, i.e. "
            "2 I - F, for F): the deformation reversed, in the energy, the stress and the "
            "stiffness (the force's sign then flipped by the chain rule in u)",
            Spec(deformation="reversed"),
        ),
        (
            "c-off-diagonal-lost",
            "the off-diagonal (shear) entries of C lost: the energy of diag(C) (an eigen-solver "
            "reading the empty triangle of a C stored in one triangle, or the shear strains "
            "dropped), its stretches the square roots of C_11, C_22, C_33",
            Spec(deformation="c-diagonal"),
        ),
        (
            "rotation-ignored",
            "the symmetric part of F, (F + F^T)/2, used for F: the rotation ignored (F taken for "
            "its stretch U, as if F = U)",
            Spec(deformation="symmetric"),
        ),
    ]
    out.append(
        (
            "deformed-volume",
            "the energy weighted by the deformed volume: J W integrated for W (a density per "
            "current volume used per rest volume)",
            Spec(deformed_volume=True),
        )
    )
    out += [
        (
            "stretch-squares",
            "principal stretches confused with their squares: the eigenvalues of C used as the "
            "stretches (their power doubled)",
            Spec(eigen_power=2.0),
        ),
        (
            "stretch-squares",
            "principal stretches confused with their squares: the stretches used as the "
            "eigenvalues of C (their power halved)",
            Spec(eigen_power=0.5),
        ),
        (
            "stretch-squares",
            "principal stretches confused with their squares: I1 = tr(C^2), the sum of the "
            "stretches^4, for tr C",
            Spec(i1="trC2"),
        ),
        (
            "stretch-squares",
            "principal stretches confused with their squares: I1 = the sum of the stretches for "
            "the sum of their squares",
            Spec(i1="trU"),
        ),
    ]
    out += [
        (
            "i1-from-part-of-F",
            "I1 = tr(F F) for tr C = tr(F^T F): the transpose lost in C (exact where F is "
            "symmetric)",
            Spec(i1="trFF"),
        ),
        (
            "i1-from-part-of-F",
            "I1 = F_11^2 + F_22^2 + F_33^2 for tr C = sum_ij F_ij^2: the first invariant taken "
            "from the diagonal of F (C_ii as F_ii^2; exact where F is diagonal)",
            Spec(i1="diagF"),
        ),
    ]
    # The strain measure: only formulas written in E change (the dedupe below drops the rest).
    out += [
        (
            "strain-no-half",
            "Green's strain without its 1/2: E = C - I used for E = (C - I)/2",
            Spec(strain="no-half"),
        ),
        (
            "strain-small",
            "the linearised (small) strain (F + F^T)/2 - I used for Green's E = (C - I)/2",
            Spec(strain="small"),
        ),
        (
            "strain-isochoric",
            "the strain of the isochoric C_bar = J^(-2/3) C, (C_bar - I)/2, used for Green's "
            "E = (C - I)/2 (the decoupled split's habit carried into a strain-based energy)",
            Spec(strain="isochoric"),
        ),
    ]
    try:
        exponents = _exponents(model)
    except Exception:  # noqa: BLE001
        exponents = []
    for r, words in _R_WORDS.items():
        if exponents:
            out.append(
                (
                    "isochoric-power",
                    f"the isochoric power of J {words}: every J^p with p not an integer "
                    f"({', '.join(exponents)}) taken as J^({r:g} p)",
                    Spec(j_power=r),
                )
            )
        if len(exponents) > 1:
            for e in exponents:
                out.append(
                    (
                        "isochoric-power",
                        f"the isochoric power of J {words} in one place: J^({e}) taken as "
                        f"J^({r:g} x {e})",
                        Spec(j_power=r, j_power_of=e),
                    )
                )
    out.append(
        (
            "j-power-out-of-exp",
            "the isochoric power of J applied outside the exponential instead of to its argument "
            "inside: exp(J^p X) taken as J^p (exp(X) - 1) + 1, i.e. c (exp(J^p X) - 1) computed "
            "as c J^p (exp(X) - 1), J^p read as a factor of the whole exponential term",
            Spec(j_out_of_exp=True),
        )
    )
    kept: List[KinematicVariant] = []
    seen = {base}
    for code, title, spec in out:
        try:
            text = _formula_text(model, spec)
        except Exception:  # noqa: BLE001 - the rewrite does not apply to this formula
            continue
        if text in seen:
            continue
        seen.add(text)
        sign = -1.0 if spec.deformation == "reversed" else 1.0
        kept.append(KinematicVariant(code, title, spec, force_sign=sign))
    if _uses_frame(model):  # a rewrite of the frame alone: no formula text tells it apart
        kept.append(
            KinematicVariant(
                "frame-deformed",
                "the fibre frame taken in the deformed configuration and re-orthonormalised: "
                "F R pushed forward, fibre normalised, sheet made orthogonal to it (Gram-Schmidt), "
                "normal their cross product",
                Spec(),
                orthonormalised=True,
            )
        )
    return kept


def _exponents(model: Any) -> List[str]:
    """The non-integer exponents of J in the formula, printed with parameters as plain numbers
    (a Spec's j_power_of is matched on that print).
    """
    from conformance.diagnosis.energy_terms import symbolic

    W, entered, _ = symbolic(model, Spec(), _Symbols(model))
    out = []
    for e in j_power_exponents(W):
        for c, name in entered:  # the symbols printed as the parameters' names
            e = re.sub(re.escape(str(c)) + r"(?![\d}])", name, e)
        out.append(e)
    return out
