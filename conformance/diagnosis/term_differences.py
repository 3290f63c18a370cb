"""One scalar second derivative of the energy taken by finite differences inside the engine.

The readings of one tangent term (:mod:`conformance.diagnosis.second_derivative`: the term
d2W/dI2 dI (x) dI; :func:`conformance.diagnosis.diagnose.diagnose`: the volumetric U''(J)) fit
the stiffness error cell by cell as lambda_c V_c g_c g_c^T, lambda_c the engine's error on
psi''(I_c). They say WHERE the error is. When lambda_c is a tiny fraction of psi''(I_c) itself
(1e-7 .. 1e-3), the term is neither left out nor scaled: it is perturbed, and the usual
perturbation is a difference quotient of psi' with a step h. Its error is, cell by cell,

    forward   (psi'(I + h) - psi'(I)) / h - psi''(I)      ~  (h / 2)   psi'''(I)
    backward  (psi'(I) - psi'(I - h)) / h - psi''(I)      ~ -(h / 2)   psi'''(I)
    central   (psi'(I + h) - psi'(I - h)) / 2h - psi''(I) ~  (h^2 / 6) psi''''(I)

with one unknown h, or, where the engine's step is relative (h I: a fraction of the value),
those errors times I (forward, backward) or I^2 (central): both kinds are fitted, and where
both fit (the cells' values too close together) both are said. psi's derivatives are those
of the oracle's own declared energy (:func:`conformance.diagnosis.variants.energy_expression`)
in that invariant, the others held, evaluated at each cell's invariants by differences with a
wide step (what is fitted is the shape over cells, to a few per cent). A step is named only
when one scheme reproduces lambda_c over cells with at least three distinct values of the
invariant (on fewer, any smooth error fits); otherwise the term is said to be slightly off, not
wrong, at "partly explains". A pressure U'(J) taken by differences of U (a mixed engine's p)
is read the same way one derivative down (:func:`pressure_difference_reading`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any, Dict, Optional, Tuple

import numpy as np

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, PARTIAL, Finding
from conformance.diagnosis.fractions import simple_fraction

__all__ = [
    "SMALL",
    "cell_invariants",
    "declared_energy",
    "invariant_derivatives",
    "DifferenceStep",
    "fit_difference_step",
    "term_difference_finding",
    "term_difference_reading",
    "energy_values",
    "rounding_scale",
    "pressure_difference_finding",
    "pressure_difference_reading",
    "volumetric_slip_finding",
]

#: lambda_c relative to psi''(I_c) (RMS over cells) below which the term is perturbed, not
#: wrong (a term left out, scaled or linearised is off by 1e-2 of itself or more).
SMALL = 1e-3

#: Relative residual of lambda_c after the fitted scheme, below which the step is named.
FITS = 0.02

#: The finding codes whose term is read: code -> invariant ("J" for the volumetric U(J)).
TERM_CODES = ("tangent-curvature", "volumetric")


def cell_invariants(F: np.ndarray) -> Dict[str, np.ndarray]:
    """The scalar invariants (each (m,)) of deformation gradients F (m, 3, 3)."""
    C = F.swapaxes(1, 2) @ F
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    return {
        "J": J,
        "I1": I1,
        "I2": I2,
        "I3": J**2,
        "I1b": J ** (-2.0 / 3.0) * I1,
        "I2b": J ** (-4.0 / 3.0) * I2,
    }


def declared_energy(model: Any) -> Any:
    """The oracle's declared energy of ``model`` as a user energy (evaluable on arrays of the
    scalar invariants), or None when it has no scalar formula.
    """
    from conformance.diagnosis.variants import energy_expression
    from reference_fem.user_energy import UserEnergy

    expr = energy_expression(model)
    if expr is None:
        return None
    try:
        return UserEnergy(expr[0], dict(expr[1]))
    except (ValueError, TypeError):
        return None


def invariant_derivatives(
    model: Any, invariants: Dict[str, np.ndarray], name: str
) -> Optional[np.ndarray]:
    """(4, m): the 1st to 4th derivatives of the declared energy in invariant ``name`` at each
    cell's invariants (the others held), or None when the energy has no scalar formula, does not
    read ``name``, or is not finite around the cells' values.
    """
    energy = declared_energy(model)
    if (
        energy is None
        or name not in energy.variables
        or not set(energy.variables) <= set(invariants)
    ):
        return None
    x = invariants[name]
    # A wide step: the derivatives' shape over cells is what matters; the 4th difference's
    # round-off is u |W| / d^4 ~ 1e-8 of it at d = 1e-2, its truncation d^2 ~ 1e-4.
    d = 1e-2 * np.maximum(np.abs(x), 1.0)

    def W(k: int) -> np.ndarray:
        shifted = {**invariants, name: x + k * d}
        with np.errstate(all="ignore"):
            return np.asarray(energy.evaluate(shifted.__getitem__, np.log, np.exp, np.sqrt))

    w = {k: W(k) for k in range(-3, 4)}
    out = np.stack(
        [
            (w[1] - w[-1]) / (2 * d),
            (w[1] - 2 * w[0] + w[-1]) / d**2,
            (w[2] - 2 * w[1] + 2 * w[-1] - w[-2]) / (2 * d**3),
            (w[2] - 4 * w[1] + 6 * w[0] - 4 * w[-1] + w[-2]) / d**4,
        ]
    )
    return out if np.all(np.isfinite(out)) else None


def energy_values(model: Any, invariants: Dict[str, np.ndarray]) -> np.ndarray:
    """(m,) the declared energy at each cell's invariants (the scale of its rounding)."""
    energy = declared_energy(model)
    with np.errstate(all="ignore"):
        return np.asarray(energy.evaluate(invariants.__getitem__, np.log, np.exp, np.sqrt))


@dataclass(frozen=True)
class DifferenceStep:
    """scheme ("forward", "backward", "central"); step h (in the invariant's units, or with
    ``proportional`` a fraction of the invariant's value: h I); residual: ||lambda -
    prediction|| / ||lambda||; relative: RMS of lambda_c / psi''(I_c); distinct: how many
    distinct values of the invariant the cells hold; other: the residual of the other kind of
    step (absolute for a proportional one and back), the same scheme; rounded: the residual is
    above FITS but every cell's is within the quotient's rounding (:func:`_within_rounding`).
    """

    scheme: str
    step: float
    residual: float
    relative: float
    distinct: int
    proportional: bool = False
    other: float = float("inf")
    rounded: bool = False

    @property
    def fits(self) -> float:
        """The residual as judged: FITS when the rest is the quotient's rounding."""
        return FITS if self.rounded else self.residual

    @property
    def named(self) -> bool:
        return self.fits <= FITS and self.distinct >= 3 and self.step > 0


def fit_difference_step(
    lam: np.ndarray, derivs: np.ndarray, x: np.ndarray, noise: Optional[np.ndarray] = None
) -> DifferenceStep:
    """The scheme and step whose truncation error best reproduces lam (m,) (engine minus oracle
    psi''), derivs (4, m) psi' .. psi'''' at the cells' values x (m,). noise (m,): per cell,
    what rounding leaves in the differenced function's difference (:func:`rounding_scale`);
    when given, a step whose residual exceeds :data:`FITS` is still named when every cell's
    residual is within that rounding over the step (:func:`_within_rounding`).
    """
    d2, d3, d4 = derivs[1], derivs[2], derivs[3]
    nl = float(np.linalg.norm(lam))
    rel = float(np.sqrt(np.mean((lam / np.where(d2 == 0, np.inf, d2)) ** 2)))
    distinct = int(np.unique(np.round(x, 9)).size)
    best = DifferenceStep("forward", float("nan"), float("inf"), rel, distinct)
    # A step proportional to the value (h I, as engines write a relative step) scales each
    # cell's truncation error by I (forward, backward) or I^2 (central).
    schemes = (("forward", d3 / 2, x), ("backward", -d3 / 2, x), ("central", d4 / 6, x * x))
    for scheme, basis, scale in schemes:
        left = {}
        for proportional, b in ((False, basis), (True, basis * scale)):
            nb = float(b @ b)
            if nb == 0 or nl == 0:
                continue
            a = float(lam @ b) / nb
            if a > 0:
                step = a if scheme != "central" else float(np.sqrt(a))
                res = float(np.linalg.norm(lam - a * b)) / nl
                rounded = False
                if res > FITS and noise is not None:  # the rest may be the quotient's rounding
                    h = step * x if proportional else step
                    rounded = _within_rounding(lam, a * b, noise / h)
                left[proportional] = DifferenceStep(
                    scheme, step, res, rel, distinct, proportional, rounded=rounded
                )
        for proportional, fit in left.items():
            other = left.get(not proportional)
            fit = replace(fit, other=float("inf") if other is None else other.fits)
            if fit.fits < best.fits or (fit.fits == best.fits and fit.residual < best.residual):
                best = fit
    return best


def rounding_scale(f: np.ndarray, df: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(m,) per cell, what rounding leaves in f(x + h) - f(x) for a function of value f and
    slope df at x (each (m,)): the values' own rounding and the step's (x + h is rounded to
    x's precision, so the step taken is h + O(eps |x|)), a few units each. Over h it is the
    rounding of the difference quotient.
    """
    return 4.0 * np.finfo(np.float64).eps * (np.abs(f) + np.abs(df * x))


#: With rounding allowed for, the truncation error must still carry most of lam: at most this
#: fraction of it left (pure rounding noise, which no step's truncation shapes, leaves nearly
#: all of it).
ROUNDED_FITS = 0.25


def _within_rounding(lam: np.ndarray, predicted: np.ndarray, rounding: np.ndarray) -> bool:
    """True when ``predicted`` leaves of lam (each (m,)) in every cell at most its rounding
    (m,) plus FITS of its prediction, and at most :data:`ROUNDED_FITS` of lam over all cells.
    """
    rest = lam - predicted
    if np.linalg.norm(rest) > ROUNDED_FITS * np.linalg.norm(lam):
        return False
    left = np.abs(rest) / (rounding + FITS * np.abs(predicted) + 1e-300)
    return bool(np.all(left <= 1.0))


def _term_words(finding: Finding) -> tuple[str, str]:
    """(invariant, the term in words) of a term finding."""
    if finding.code == "volumetric":
        return "J", "d2U/dJ2 of the volumetric (J-only) energy U"
    name = finding.figures["invariant"]
    return name, f"d2W/d{name}2 (the term d2W/d{name}2 d{name} (x) d{name})"


def _left_words(fit: DifferenceStep, name: str) -> str:
    """What the fitted step leaves, in words."""
    left = f"left: {100 * fit.residual:.1f} % over {fit.distinct} distinct values of {name}"
    if fit.rounded:
        left += (
            ", in every cell within the rounding of such a quotient, a few eps times the "
            "differenced function and its change over the step's own rounding, over h"
        )
    return left


def _step_words(fit: DifferenceStep, name: str, order: int) -> Tuple[str, str]:
    """(the fitted step, the truncation error) in words, for the ``order``-th derivative in
    ``name`` taken by differences of the one below it.
    """
    if fit.scheme == "central":
        error = f"h^2 / 6 d{order + 2}W/d{name}{order + 2}"
    else:
        error = f"h / 2 d{order + 1}W/d{name}{order + 1}"
    if fit.other <= FITS:  # both kinds of step fit: the values of I are too close to tell
        return (
            f"step h = {fit.step:.2g} (absolute, in {name}, or relative, h {name}: the cells' "
            f"{name} are too close to tell)",
            error,
        )
    if fit.proportional:
        error = error.replace("h^2", f"(h {name})^2", 1).replace("h / 2", f"h {name} / 2", 1)
        return f"relative step h = {fit.step:.2g} (each cell's step h {name})", error
    return (
        f"absolute step h = {fit.step:.2g} (in {name}; or the same step in a variable "
        "proportional to it)",
        error,
    )


def term_difference_finding(
    finding: Finding, lam: np.ndarray, derivs: np.ndarray, x: np.ndarray
) -> Optional[Finding]:
    """The term finding restated when lam (m,) is a small perturbation of psi'' (None when it
    is not small: the term is then wrong, and ``finding`` stands).
    """
    fit = fit_difference_step(lam, derivs, x, rounding_scale(derivs[0], derivs[1], x))
    if not fit.relative < SMALL:
        return None
    name, term = _term_words(finding)
    figures = {
        **finding.figures,
        "invariant": name,  # the term's variable (J: consistent with one J's exact fits)
        "relative_to_term": fit.relative,
        "scheme": fit.scheme,
        "step": fit.step,
        "step_residual": fit.residual,
        "rounded": fit.rounded,
        "distinct_values": fit.distinct,
        "restates": finding.title,  # what the other cases of the kit may settle on
    }
    size = (
        f"{finding.evidence}; the fitted error is {fit.relative:.1e} of the oracle's {term} "
        "itself (RMS over cells): a small perturbation of that term, not a term left out or "
        "scaled"
    )
    if fit.named:
        step, order = _step_words(fit, name, 2)
        figures["proportional"] = fit.proportional
        return Finding(
            "finite-difference-term",
            f"{term} taken by {fit.scheme} finite differences of its first derivative in "
            f"{name}, {step}, inside an otherwise analytic tangent",
            finding.strength,
            f"{size}; cell by cell it is the truncation error of {fit.scheme} differences, "
            f"{order} of the oracle's energy, with one fitted step ({_left_words(fit, name)})",
            figures,
        )
    why = (
        f"the state holds {fit.distinct} distinct value(s) of {name}: too few to tell a "
        "difference step from another small error"
        if fit.distinct < 3
        else f"no difference scheme reproduces it over the cells (best: {fit.scheme}, "
        f"{100 * fit.residual:.0f} % left)"
    )
    return Finding(
        finding.code,
        f"{term} slightly off (by {fit.relative:.1e} of itself), e.g. by finite differences "
        "of its first derivative",
        PARTIAL,
        f"{size}; {why}",
        figures,
    )


#: A volumetric U''(J) slip is named when lam is k2 U'' + k1 U'/J to this relative residual (the
#: derivatives are wide-step differences, good to about 1e-4) with k1, k2 simple fractions.
SLIP_FITS = 2e-3


def _simple(k: float) -> Optional[Fraction]:
    """The number k as a fraction with denominator at most 3 (to 1e-3 of max(1, |k|)), or None."""
    return simple_fraction(k, 3, 1e-3)


def volumetric_slip_finding(
    finding: Finding, lam: np.ndarray, derivs: np.ndarray, J: np.ndarray
) -> Optional[Finding]:
    """The volumetric finding restated with the engine's U''(J) as a simple combination of the
    oracle's U'' and U'/J: lam (m,) = k2 U'' + k1 U'/J (engine minus oracle per cell), the
    derivatives (4, m) at the cells' J (m,). U'/J is what a quotient rule's sign slip leaves
    (U' = u/J differentiated as u'/J + u/J^2: 2 U'/J too much). None unless J takes at least
    three values, U'' and U'/J are not proportional over the cells, and the fit holds with
    simple fractions.
    """
    if np.unique(np.round(J, 9)).size < 3:
        return None
    A = np.stack([derivs[1], derivs[0] / J], axis=1)
    nl = float(np.linalg.norm(lam))
    if nl == 0 or np.linalg.cond(A / np.linalg.norm(A, axis=0)) > 1e6:
        return None  # U'' and U'/J proportional here (a power of J): a factor, said elsewhere
    (k2, k1), *_ = np.linalg.lstsq(A, lam, rcond=None)
    left = float(np.linalg.norm(lam - A @ np.array([k2, k1]))) / nl
    q2, q1 = _simple(float(k2)), _simple(float(k1))
    if left > SLIP_FITS or q2 is None or q1 is None:
        return None

    def times(q: Fraction, what: str) -> str:
        return "" if q == 0 else (what if q == 1 else f"{q} {what}")

    engine = " + ".join(w for w in (times(1 + q2, "U''"), times(q1, "U'/J")) if w)
    engine = engine.replace("+ -", "- ")
    why = (
        " (U' = u/J differentiated with + u/J^2 where - u/J^2 belongs: the quotient rule's "
        "sign, e.g. k0 (1 + ln J)/J^2 for k0 (1 - ln J)/J^2)"
        if q2 == 0 and q1 == 2
        else ""
    )
    return Finding(
        finding.code,
        f"volumetric tangent: d2U/dJ2 written wrongly, the engine's is {engine or '0'} where "
        f"U'' belongs{why} (the force matches)",
        finding.strength,
        f"{finding.evidence}; cell by cell the fitted error is {float(k2):.4g} U'' + "
        f"{float(k1):.4g} U'/J of the oracle's U (left: {100 * left:.2f} % over "
        f"{np.unique(np.round(J, 9)).size} distinct J)",
        {**finding.figures, "d2U_factor": float(k2), "dU_over_J": float(k1)},
    )


def term_difference_reading(diag, ci, out, ref):
    """``diag`` whose first cause is one tangent term (curvature or volumetric, the force
    right) with that finding restated as a finite-difference step or a small perturbation when
    the evidence says so; unchanged otherwise.
    """
    from scipy.sparse import csr_matrix

    from conformance.diagnosis.second_derivative import fit_invariant_curvature

    causes = diag.causes
    if not causes or causes[0].code not in TERM_CODES or causes[0].strength != FULL:
        return diag
    if any(f.code == "ambiguous" for f in diag.findings):
        return diag  # several terms fit: which one is perturbed is not known
    if diag.errors.force > diag.tolerances.force:
        return diag
    first = causes[0]
    name = "J" if first.code == "volumetric" else first.figures.get("invariant")
    if name is None:
        return diag
    F = cell_kinematics(ci.points, ci.cells, ci.positions)[2]
    inv = cell_invariants(F)
    derivs = invariant_derivatives(ci.model, inv, name)
    if derivs is None:
        return diag
    K_o = csr_matrix(ref.stiffness)
    D = (csr_matrix(out.stiffness) - K_o).tocsr()
    _, lam = fit_invariant_curvature(ci.points, ci.cells, ci.positions, D, K_o, name)
    new = term_difference_finding(first, lam, derivs, inv[name])
    if new is None and name == "J":
        new = volumetric_slip_finding(first, lam, derivs, inv[name])
    if new is None:
        return diag
    return replace(diag, findings=[new if f is first else f for f in diag.findings])


#: A pressure by differences of U is named only with a small fitted step (in J, or relative):
#: a larger one is no difference quotient an engine would write.
MAX_PRESSURE_STEP = 1e-2


def pressure_difference_finding(
    dU1: np.ndarray, values: np.ndarray, derivs: np.ndarray, J: np.ndarray, evidence: str
) -> Optional[Finding]:
    """The engine's pressure U'(J) as a difference quotient of U, or None: dU1 (m,) the
    engine-minus-oracle U' per cell (its U'' the oracle's), values (m,) the energy and derivs
    (4, m) its first to fourth derivatives in J at the cells' J (m,). The truncation error of a
    difference of U is that of U'' from U' one order lower (forward h/2 U'', central
    h^2/6 U'''), so the same fit applies one derivative down, its rounding from U's values.
    """
    lower = np.stack([np.zeros_like(derivs[0]), derivs[0], derivs[1], derivs[2]])
    fit = fit_difference_step(dU1, lower, J, rounding_scale(values, derivs[0], J))
    if not (fit.named and fit.step <= MAX_PRESSURE_STEP):
        return None
    step, error = _step_words(fit, "J", 1)
    return Finding(
        "finite-difference-pressure",
        f"the pressure dU/dJ of the volumetric (J-only) energy U taken by {fit.scheme} finite "
        f"differences of U, {step}, inside an otherwise analytic stress and tangent (d2U/dJ2 "
        "right)",
        FULL,
        f"{evidence}; cell by cell the fitted error of dU/dJ is the truncation error of "
        f"{fit.scheme} differences, {error} of the oracle's energy, with one fitted step "
        f"({_left_words(fit, 'J')})",
        {
            "invariant": "J",
            "scheme": fit.scheme,
            "step": fit.step,
            "proportional": fit.proportional,
            "step_residual": fit.residual,
            "rounded": fit.rounded,
            "distinct_values": fit.distinct,
        },
    )


def pressure_difference_reading(diag, ci, out, ref, s):
    """``diag`` (nothing named, the force wrong) with the pressure named as a difference
    quotient of U when the error is, cell by cell, a change of U'(J) alone (the tangent's U''
    right: the stiffness moves only through p) of that form; unchanged otherwise.
    """
    from scipy.sparse import csr_matrix

    from conformance.diagnosis.tangent import fit_volumetric

    tol = diag.tolerances
    if diag.errors.force <= tol.force:
        return diag
    f_o = np.asarray(ref.force, dtype=np.float64).reshape(-1, 3)
    df = np.asarray(out.force, dtype=np.float64).reshape(-1, 3) - f_o
    D = (csr_matrix(out.stiffness) - csr_matrix(ref.stiffness)).tocsr()
    fit = fit_volumetric(ci.points, ci.cells, ci.positions, df, D, s.force, s.stiffness)
    if fit is None or fit.force_residual > tol.force or fit.stiffness_residual > tol.stiffness:
        return diag
    inv = cell_invariants(cell_kinematics(ci.points, ci.cells, ci.positions)[2])
    derivs = invariant_derivatives(ci.model, inv, "J")
    if derivs is None:
        return diag
    # U'' right: its fitted change is round-off beside the pressure's own change over J
    if np.linalg.norm(fit.dU2) > 1e-6 * np.linalg.norm(fit.dU1 / fit.J):
        return diag
    found = pressure_difference_finding(
        fit.dU1,
        energy_values(ci.model, inv),
        derivs,
        fit.J,
        f"a per-cell change of dU/dJ alone (d2U/dJ2 unchanged) leaves force error "
        f"{fit.force_residual:.1e} and stiffness error {fit.stiffness_residual:.1e}",
    )
    if found is None:
        return diag
    return replace(diag, findings=[found, *(f for f in diag.findings if f.code != "unexplained")])
