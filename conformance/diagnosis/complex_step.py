"""A Voigt material tangent by the complex step or by central differences of S, in the
components of E or of C: the step's truncation error, and a relative step's divisor.

An engine that builds D = dS/dE column by column from its own stress routine,

    complex step:  D e_B = Im S(E + i h_B e_B) / h_B,
    central:       D e_B = (S(E + h_B e_B) - S(E - h_B e_B)) / (2 h_B),

(e_B a unit step of the B-th Voigt strain component, engineering shear) is exact but for its
truncation: -(h_B^2 / 6) d2D_AB/d(eps_B)^2 in column B for the complex step, +(h_B^2 / 6) for
central differences (the complex step has no round-off to fear, so a step of 1e-2 chosen "to be
safe" shows its h^2). The one-sided scheme's h/2 is
:mod:`conformance.diagnosis.strain_differences`'. How h_B relates to one step h depends on where
the engine steps (:data:`CONVENTIONS`): in E with engineering shears, in C's components (C = I +
2 E: a normal strain moved by h/2, a shear's gamma by h, as C_IJ and C_JI move together) or in C
with a step relative to the component, h max(|C_B|, 1).

The curvature d2D_AB/d(eps_B)^2 is taken per cell by second differences of the oracle's tangent
(MJED's element matrices on the mesh with its cells pulled apart) along a path on which E moves
exactly linearly: each cell deformed by the symmetric square root of C + 2 s e_B (the energy
depends on C alone), so the curvature is not polluted by the first derivative. The stiffness of
the truncation per unit h^2 is assembled for each convention and +-h^2 fitted with one unknown:
its sign tells the scheme (complex step below the oracle, central above it). Named, as partly
explaining (the next order and round-off are left), when a fit accounts for
:data:`conformance.diagnosis.strain_differences.EXPLAINED` of the stiffness error, the force
right; the best convention said, the others that fit beside it; fits of both schemes:
ambiguous.

**A relative step's divisor.** An engine that scales its step by the component it moves,
h_B = h max(|C_B|, 1), and divides the quotient by h instead of h_B, has column B of D
multiplied by max(|C_B|, 1) (and the converse divided by it; a step h |C_B| so divided: times
|C_B|): :data:`DIVISORS`, each predicted from the oracle's per-cell tangent with nothing fitted
and named when the stiffness then matches within the tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, case_split, cell_piola
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, ambiguous, named_first
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.strain_differences import (
    EXPLAINED,
    VOIGT,
    fit_step,
    material_stiffness,
    unit_strain,
    voigt_matrix,
    voigt_tensor,
)
from conformance.judge.compare import errors

__all__ = [
    "CONVENTIONS",
    "DIVISORS",
    "strain_curvatures",
    "StepFit",
    "fit_second_order_steps",
    "divisor_findings",
    "complex_step_reading",
]

#: Second-difference step in the strain (dimensionless): truncation 1e-6 of the curvature,
#: round-off u / DELTA^2 ~ 2e-10 of the tangent.
DELTA = 1e-3

_NORMAL = np.array([True, True, True, False, False, False])


def _c_components(C: np.ndarray) -> np.ndarray:
    """(m, 6) |C_B| per cell in the Voigt order."""
    return np.abs(np.stack([C[:, i, j] for i, j in VOIGT], axis=1))


#: Where an engine steps, as (h_B / h)^2 per cell: name -> (words, C (m, 3, 3) -> (m, 6)).
CONVENTIONS: Dict[str, tuple] = {
    "E": (
        "in each Voigt component of E (engineering shears)",
        lambda C: np.ones((C.shape[0], 6)),
    ),
    "C": (
        "in each component of C (a normal strain moved by h/2, a shear's C_IJ and C_JI by h "
        "together; the same as h/2 in each tensor component of E)",
        lambda C: np.where(_NORMAL, 0.25, 1.0) * np.ones((C.shape[0], 1)),
    ),
    "C-relative": (
        "in each component of C, relative to it (h max(|C_B|, 1))",
        lambda C: (np.where(_NORMAL, 0.5, 1.0) * np.maximum(_c_components(C), 1.0)) ** 2,
    ),
}

#: A relative step's divisor slips: code -> (words, C (m, 3, 3) -> (m, 6) the column factors).
DIVISORS: Dict[str, tuple] = {
    "scaled-not-divided": (
        "the step scaled by the component it moves, h max(|C_B|, 1), but the quotient divided "
        "by h: column B of the Voigt tangent D multiplied by max(|C_B|, 1)",
        lambda C: np.maximum(_c_components(C), 1.0),
    ),
    "divided-not-scaled": (
        "the quotient divided by a relative step h max(|C_B|, 1) while the step taken was h: "
        "column B of the Voigt tangent D divided by max(|C_B|, 1)",
        lambda C: 1.0 / np.maximum(_c_components(C), 1.0),
    ),
    "scaled-by-component": (
        "the step taken as h |C_B| (relative to the component it moves) but the quotient "
        "divided by h: column B of the Voigt tangent D multiplied by |C_B|",
        _c_components,
    ),
}


def _stretch(C: np.ndarray) -> np.ndarray:
    """(m, 3, 3) the symmetric square root of symmetric positive definite C (m, 3, 3)."""
    w, V = np.linalg.eigh(C)
    return (V * np.sqrt(w)[:, None, :]) @ V.swapaxes(1, 2)


def strain_curvatures(model: Any, split: ElementSplit, points: np.ndarray) -> Optional[np.ndarray]:
    """(m, 6, 6) d2D_AB/d(eps_B)^2 per cell (D the Voigt material tangent, column B along its
    own strain component, engineering shear), by second differences of MJED's tangent with E
    moved linearly; None when MJED cannot evaluate the model there.
    """
    import mjed

    cells = split.cells
    m = cells.shape[0]
    X = points[cells]  # (m, 4, 3)
    loose = np.arange(4 * m).reshape(m, 4)
    Xc = X - X[:, :1]
    C = split.F.swapaxes(1, 2) @ split.F
    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), loose), model)

        def tangent(Cs: np.ndarray) -> np.ndarray:
            U = _stretch(Cs)
            xs = (np.einsum("mij,maj->mai", U, Xc) + X[:, :1]).reshape(-1, 3)
            fe = np.asarray(field.element_forces(xs), dtype=np.float64)
            Ke = np.asarray(field.element_stiffness(xs), dtype=np.float64)
            moved = ElementSplit(loose, 4 * m, split.V0, split.D, U, fe, Ke, 0.0)
            return voigt_matrix(cell_tensors(*cell_piola(moved), U).CC)

        D0 = tangent(C)
        out = np.empty((m, 6, 6))
        for B in range(6):
            e = 2.0 * DELTA * unit_strain(B)  # C = I + 2 E
            plus, minus = tangent(C + e), tangent(C - e)
            out[:, :, B] = (plus[:, :, B] - 2.0 * D0[:, :, B] + minus[:, :, B]) / DELTA**2
    except Exception:  # noqa: BLE001 - not an MJED material, or a moved cell it cannot take
        return None
    return out if np.all(np.isfinite(out)) else None


@dataclass(frozen=True)
class StepFit:
    """scheme ("complex step" / "central"); convention (a key of :data:`CONVENTIONS`); step: h;
    explained: the fraction of ||K - K_o|| accounted for; residual: what is left, relative to
    ||K_o||.
    """

    scheme: str
    convention: str
    step: float
    explained: float
    residual: float

    def words(self) -> str:
        quotient = (
            "Im S(E + i h e_B) / h" if self.scheme == "complex step" else "(S(+h) - S(-h)) / (2 h)"
        )
        return (
            f"a {self.scheme} of the stress S {CONVENTIONS[self.convention][0]}, "
            f"D e_B = {quotient}, step h = {self.step:.2e}: too large a step, its truncation "
            "(h^2/6) d2D/d(eps_B)^2 left in each column"
        )


def fit_second_order_steps(
    split: ElementSplit, curvature: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> List[StepFit]:
    """The fit of D = K - K_o (3n, 3n) as -+h^2 times each convention's truncation stiffness
    (curvature: (m, 6, 6) from :func:`strain_curvatures`), one unknown each, best first.
    """
    C = split.F.swapaxes(1, 2) @ split.F
    out = []
    for name, (_, weights) in CONVENTIONS.items():
        lead = curvature * weights(C)[:, None, :] / 6.0  # column B's error per unit h^2
        fit = fit_step(material_stiffness(split, voigt_tensor(lead)), D, K_o)
        if fit is None:
            continue
        scheme = "central" if fit.scheme == "forward" else "complex step"
        out.append(StepFit(scheme, name, float(np.sqrt(fit.step)), fit.explained, fit.residual))
    return sorted(out, key=lambda f: -f.explained)


def divisor_findings(split: ElementSplit, f, K, f_o, K_o, s, tol) -> List[Finding]:
    """The divisor slips of :data:`DIVISORS` whose stiffness is the engine's (K) within the
    tolerance, predicted from the oracle's per-cell tangent with nothing fitted.
    """
    t = cell_tensors(*cell_piola(split), split.F)
    Dv = voigt_matrix(t.CC)
    base = errors(f, K, None, f_o, K_o, 0.0, s)
    found = []
    for code, (words, factors) in DIVISORS.items():
        dD = Dv * (factors(t.C) - 1.0)[:, None, :]
        if not np.any(np.abs(dD) > 1e-12 * np.abs(Dv).max()):
            continue  # the slip changes nothing at this state
        e = errors(f, K, None, f_o, K_o + material_stiffness(split, voigt_tensor(dD)), 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    f"tangent-step-{code}",
                    f"a numerical tangent (complex step or differences of S) with its step and "
                    f"divisor disagreeing: {words}",
                    FULL,
                    "the oracle's per-cell Voigt tangent with its columns so scaled, assembled "
                    "with the geometric part right (nothing fitted): stiffness error "
                    f"{e.stiffness:.1e} (against {base.stiffness:.1e}); the force right",
                    {"slip": code},
                )
            )
    return found


def _step_finding(fit: StepFit, others: Sequence[StepFit] = ()) -> Finding:
    also = "".join(
        f"; stepping {CONVENTIONS[o.convention][0]} (h = {o.step:.2e}) fits nearly as well "
        f"({100 * o.explained:.2f} %)"
        for o in others
    )
    return Finding(
        "complex-step" if fit.scheme == "complex step" else "central-strain-differences",
        f"a numerical material tangent: {fit.words()}",
        PARTIAL,
        "K - K_oracle is that scheme's truncation per cell (-+(h^2/6) d2D_AB/d(eps_B)^2 in "
        "column B, from the oracle's tangent differentiated twice along each strain "
        f"component), fitted with one unknown: it accounts for {100 * fit.explained:.2f} % of "
        f"the stiffness error (left: {fit.residual:.1e}, the next order and round-off); the "
        f"sign of h^2 tells the scheme; the force matches{also}",
        {"step": fit.step, "scheme": fit.scheme, "convention": fit.convention},
    )


def complex_step_reading(diag, ci, out, ref, s, curvatures: Callable = strain_curvatures):
    """``diag`` (the force right, nothing named) with a relative step's divisor slip named
    first (exact), else a complex-step or central-difference tangent whose step's truncation
    accounts for :data:`EXPLAINED` of the stiffness error (partly); unchanged when none does.
    """
    if diag.errors.force > diag.tolerances.force:
        return diag
    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    with np.errstate(all="ignore"):
        found = divisor_findings(
            split, out.force, out.stiffness, ref.force, ref.stiffness, s, diag.tolerances
        )
        if not found:
            curvature = curvatures(ci.model, split, ci.points)
            if curvature is None:
                return diag
            K_o = sp.csr_matrix(ref.stiffness)
            D = (sp.csr_matrix(out.stiffness) - K_o).tocsr()
            fits = [
                f
                for f in fit_second_order_steps(split, curvature, D, K_o)
                if f.explained >= EXPLAINED
            ]
            if len({f.scheme for f in fits}) == 1:
                # one scheme: where it steps (the conventions weight normal and shear columns
                # differently) is a detail, the best fit said and the others beside it
                found = [_step_finding(fits[0], fits[1:])]
            else:
                found = [_step_finding(f) for f in fits]
    if len(found) > 1:
        found = ambiguous(found, "their predictions fit alike here")
    return named_first(diag, found)
