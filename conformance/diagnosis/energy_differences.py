"""The stress by differences of the energy density, cell by cell.

An engine that trusts its energy more than its stress (or has no stress routine for a
material) may take the stress by differencing the energy density W of each cell in the
components of a deformation measure. The leading error is a derivative of the exact stress, so
it can be predicted from the oracle's own per-cell tangent and fitted with one unknown, the
step h:

- **F, forward** (P_kJ = (W(F + h e_kJ) - W(F)) / h): P errs by (h / 2) A_kJkJ, A = dP/dF
  (no sum), in every component; a step relative to the entry, h max(|F_kJ|, 1), multiplies
  that by max(|F_kJ|, 1);
- **F, central** ((W(F + h e) - W(F - h e)) / (2 h)): by (h^2 / 6) dA_kJkJ / dF_kJ, the
  third derivative measured here by central differences of the oracle's A;
- **E (or C), forward in each Voigt component** (S_A = (W(E + h e_A) - W(E)) / h): S errs by
  (h / 2) e_A : CC : e_A, CC = dS/dE; a shear component moved as an engineering strain
  (E_12 = E_21 += h / 2) gives (h / 2) CC_1212, one moved as a tensor component (both by h,
  the quotient halved) twice that. Differences in C with step h are those in E with step h / 2;
- **E, central**: (h^2 / 6) dD_AA / d(eps_A), D the Voigt tangent, its derivative along the
  engineering strain measured as :mod:`conformance.diagnosis.strain_differences` does;
- **the principal stretches, forward** (a spectral engine's dW/dlambda_a = (W(lambda + h e_a)
  - W(lambda)) / h, S_a = (1/lambda_a) dW/dlambda_a): S_a errs by (h / 2) d2W/dlambda_a^2 /
  lambda_a with d2W/dlambda_a^2 = S_aa + lambda_a^2 CC_aaaa in the eigenbasis of C; in the
  eigenvalues lambda_a^2 of C instead, by h CC_aaaa / 4.

Each scheme's force per unit h (or h^2) is assembled as the element forces -V0 dP D_a and the
step fitted to the engine's force error. A scheme is named when it accounts for 99 % of that
error (the rest is round-off, u |W| / h, and the next order), the backward scheme when the
fitted forward step is negative; fully when the stiffness is right (the tangent analytic),
partly otherwise. MJED stands in for the oracle per cell (checked against it by
:func:`conformance.diagnosis.elements.element_split`); nothing is compiled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Tuple

import numpy as np

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    case_split,
    cell_piola,
    piola_element_forces,
)
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, named_first
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.strain_differences import (
    VOIGT,
    strain_derivatives,
    symmetric_from_voigt,
)

__all__ = [
    "EXPLAINED",
    "EnergyDifferenceFit",
    "energy_difference_bases",
    "fit_energy_differences",
    "energy_difference_reading",
]

#: Fraction of the force error a scheme must account for to be named.
EXPLAINED = 0.99

#: Step of the central differences of the oracle's A that measure the third derivative of W.
_PROBE = 1e-4


@dataclass(frozen=True)
class EnergyDifferenceFit:
    """scheme: "forward", "backward" or "central"; variable: what was differenced, in words;
    step: h; explained: fraction of ||f - f_o|| accounted for; residual: what is left,
    relative to ||f - f_o||.
    """

    scheme: str
    variable: str
    step: float
    explained: float
    residual: float

    def words(self) -> str:
        return (
            f"the stress taken by {self.scheme} differences of the energy density W in "
            f"{self.variable}, step h = {self.step:.2e}"
        )


Basis = Tuple[str, str, Callable[[], Optional[np.ndarray]]]


def _piola_forces(split: ElementSplit, dP: np.ndarray) -> np.ndarray:
    """(n, 3) the assembled force of per-cell first Piola stresses dP (m, 3, 3)."""
    return assemble(split.cells, split.n, piola_element_forces(split.V0, split.D, dP), None)[0]


def _second_piola_forces(split: ElementSplit, dS: np.ndarray) -> np.ndarray:
    """(n, 3) the assembled force of second Piola stresses dS (m, 3, 3) at the split's F."""
    return _piola_forces(split, split.F @ dS)


def _f_diagonal(A: np.ndarray) -> np.ndarray:
    """(m, 3, 3) A_kJkJ (no sum) of A = dP/dF (m, 3, 3, 3, 3)."""
    return np.einsum("mkjkj->mkj", A)


def _e_forward(split: ElementSplit, shear: float) -> np.ndarray:
    """The force of (1/2) e_A : CC : e_A per Voigt component A, the shear ones times ``shear``."""
    P, A = cell_piola(split)
    CC = cell_tensors(P, A, split.F).CC
    values = np.stack([CC[:, i, j, i, j] for i, j in VOIGT], axis=1)
    values[:, 3:] *= shear
    return _second_piola_forces(split, 0.5 * symmetric_from_voigt(values))


def _principal_forward(split: ElementSplit, squares: bool) -> np.ndarray:
    """The force of a forward difference's error per unit step in each principal stretch
    lambda_a (W(lambda) of a spectral engine, S_a = (1/lambda_a) dW/dlambda_a), or in each
    eigenvalue mu_a = lambda_a^2 of C (S_a = 2 dW/dmu_a): per cell, in the eigenbasis N_a of C,
    dS_a = (1/2) (S_aa + lambda_a^2 CC_aaaa) / lambda_a, or CC_aaaa / 4.
    """
    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    w, N = np.linalg.eigh(t.C)
    S_aa = np.einsum("mIa,mIJ,mJa->ma", N, t.S, N)
    CC_aaaa = np.einsum("mIa,mJa,mKa,mLa,mIJKL->ma", N, N, N, N, t.CC, optimize=True)
    if squares:
        values = CC_aaaa / 4.0
    else:
        values = 0.5 * (S_aa + w * CC_aaaa) / np.sqrt(w)
    dS = np.einsum("mIa,ma,mJa->mIJ", N, values, N)
    return _second_piola_forces(split, dS)


def _f_central(model: Any, split: ElementSplit, points: np.ndarray) -> Optional[np.ndarray]:
    """The force of (1/6) dA_kJkJ / dF_kJ, measured by central differences of the oracle's A."""
    from conformance.diagnosis.routine_inputs import piola_at

    third = np.empty(split.F.shape)
    for k in range(3):
        for j in range(3):
            E = np.zeros((3, 3))
            E[k, j] = _PROBE
            plus = piola_at(model, points, split, split.F + E)
            minus = piola_at(model, points, split, split.F - E)
            if plus is None or minus is None:
                return None
            third[:, k, j] = (plus[1][:, k, j, k, j] - minus[1][:, k, j, k, j]) / (2 * _PROBE)
    return _piola_forces(split, third / 6.0)


def _e_central(model: Any, split: ElementSplit, points: np.ndarray) -> Optional[np.ndarray]:
    """The force of (1/6) dD_AA / d(eps_A), D the Voigt tangent (engineering shear)."""
    dD = strain_derivatives(model, split, points)
    if dD is None:
        return None
    values = np.einsum("mAAA->mA", dD) / 6.0
    return _second_piola_forces(split, symmetric_from_voigt(values))


def energy_difference_bases(model: Any, split: ElementSplit, points: np.ndarray) -> List[Basis]:
    """(scheme, variable in words, the force error per unit h (forward) or h^2 (central), or
    None where MJED cannot evaluate it), computed lazily: the central ones cost MJED
    evaluations at moved F.
    """
    P, A = cell_piola(split)
    diag = _f_diagonal(A)
    relative = np.maximum(np.abs(split.F), 1.0)
    return [
        ("forward", "each component of F", lambda: _piola_forces(split, 0.5 * diag)),
        (
            "forward",
            "each component of F with a step relative to it, h max(|F_kJ|, 1)",
            lambda: _piola_forces(split, 0.5 * diag * relative),
        ),
        (
            "forward",
            "each Voigt component of the Green strain E (engineering shear, E_12 = E_21 moved by "
            "h/2; in C the step is twice this)",
            lambda: _e_forward(split, 1.0),
        ),
        (
            "forward",
            "each Voigt component of the Green strain E (a shear pair E_12 = E_21 moved by h, "
            "the quotient halved; in C the step is twice this)",
            lambda: _e_forward(split, 2.0),
        ),
        (
            "forward",
            "each principal stretch lambda_a (W(lambda_1, lambda_2, lambda_3) of a spectral "
            "engine, S_a = (1/lambda_a) dW/dlambda_a)",
            lambda: _principal_forward(split, False),
        ),
        (
            "forward",
            "each eigenvalue lambda_a^2 of C (W of the principal squares, "
            "S_a = 2 dW/d(lambda_a^2))",
            lambda: _principal_forward(split, True),
        ),
        ("central", "each component of F", lambda: _f_central(model, split, points)),
        (
            "central",
            "each Voigt component of the Green strain E (engineering shear)",
            lambda: _e_central(model, split, points),
        ),
    ]


def _fit(basis: np.ndarray, error: np.ndarray) -> Tuple[float, float]:
    """(coefficient, explained fraction) of error ~ coefficient x basis, one unknown."""
    b, e = np.ravel(basis), np.ravel(error)
    bb, ee = float(b @ b), float(np.linalg.norm(e))
    if bb == 0.0 or ee == 0.0 or not np.isfinite(bb):
        return 0.0, 0.0
    c = float(b @ e) / bb
    return c, 1.0 - float(np.linalg.norm(e - c * b)) / ee


def fit_energy_differences(
    model: Any, split: ElementSplit, points: np.ndarray, error: np.ndarray
) -> Optional[EnergyDifferenceFit]:
    """The first scheme whose fitted step accounts for :data:`EXPLAINED` of the force error
    (n, 3) (engine minus oracle), forward ones first; None when none does.
    """
    for scheme, variable, make in energy_difference_bases(model, split, points):
        basis = make()
        if basis is None or not np.all(np.isfinite(basis)):
            continue
        c, explained = _fit(basis, error)
        if explained < EXPLAINED:
            continue
        if scheme == "central":
            if c <= 0.0:
                continue
            step, name = float(np.sqrt(c)), "central"
        else:
            step, name = abs(c), "forward" if c > 0 else "backward"
        return EnergyDifferenceFit(name, variable, step, explained, 1.0 - explained)
    return None


def energy_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force wrong, nothing named) with the stress by differences of the energy
    named first when a scheme fits the force error; unchanged otherwise.
    """
    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    error = np.asarray(out.force, dtype=float) - np.asarray(ref.force, dtype=float)
    with np.errstate(all="ignore"):
        fit = fit_energy_differences(ci.model, split, ci.points, error)
    if fit is None:
        return diag
    tangent_right = diag.errors.stiffness <= diag.tolerances.stiffness
    order = "h^2" if fit.scheme == "central" else "h"
    return named_first(
        diag,
        [
            Finding(
                "energy-finite-difference",
                f"a finite-difference stress: {fit.words()}",
                FULL if tangent_right else PARTIAL,
                f"the force error is that scheme's truncation error (order {order}, predicted "
                "cell by cell from the oracle's exact tangent) with one unknown step: it "
                f"accounts for {100 * fit.explained:.2f} % of it (left: "
                f"{fit.residual:.1e} of the error, round-off and the next order); "
                + (
                    "your stiffness is right (an exact tangent of the exact stress)"
                    if tangent_right
                    else "your stiffness is wrong as well, which this does not explain"
                ),
                {
                    "scheme": fit.scheme,
                    "variable": fit.variable,
                    "step": fit.step,
                    "explained": fit.explained,
                },
            )
        ],
    )
