"""A first elasticity tensor A = dP/dF by central differences of P in each component of F.

An engine that differentiates its first Piola stress numerically, column by column,

    A[:, :, l, L] ~ (P(F + h e_l e_L) - P(F - h e_l e_L)) / (2 h),

errs by h^2/6 times the third derivative of P along that component, the round-off aside. The
one-sided scheme's leading error is a second derivative, fitted by
:mod:`conformance.diagnosis.strain_differences` ("first-elasticity"); this one is measured
per unit h^2 by simulating the scheme with a larger step (:data:`PROBE`, the stress from MJED at
each moved F, per cell) against the exact column of the oracle's tangent, assembled as
V0 D_aI dA_kIlL D_bL, and h^2 fitted with one unknown. Named, partly explaining (round-off and
the higher orders are left), when it accounts for 99 % of the stiffness error, as the other
difference readings are. NumPy only: no oracle form is compiled.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola
from conformance.diagnosis.strain_differences import (
    StrainDifferenceFit,
    fit_step_squared,
)

__all__ = ["PROBE", "central_piola_basis", "central_piola_fit", "central_difference_reading"]

#: The step of the simulated scheme whose error per unit h^2 is the basis (its O(h^4) rest is
#: 1e-6 of it; its round-off u |P| / h, 1e-13 of P).
PROBE = 1e-3


def central_piola_basis(model: Any, split: ElementSplit, points: np.ndarray):
    """(3n, 3n) the assembled error per unit h^2 of A by central differences of P in each
    component of F; None where MJED cannot evaluate the model at the moved F.
    """
    from conformance.diagnosis.routine_inputs import piola_at

    _, A = cell_piola(split)
    m = split.F.shape[0]
    dA = np.empty_like(A)  # [m, k, I, l, L]
    for ll in range(3):
        for L in range(3):
            E = np.zeros((3, 3))
            E[ll, L] = PROBE
            plus = piola_at(model, points, split, split.F + E, stiffness=False)
            minus = piola_at(model, points, split, split.F - E, stiffness=False)
            if plus is None or minus is None:
                return None
            column = (plus[0] - minus[0]) / (2 * PROBE)
            dA[:, :, :, ll, L] = (column - A[:, :, :, ll, L]) / PROBE**2
    if not np.all(np.isfinite(dA)):
        return None
    Ke = np.einsum("m,maI,mkIlL,mbL->makbl", split.V0, split.D, dA, split.D, optimize=True)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


def central_piola_fit(
    model: Any, split: ElementSplit, points: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> Optional[StrainDifferenceFit]:
    """The central scheme's step h when it accounts for :data:`EXPLAINED` of D = K - K_o (its
    fitted h^2 positive); None otherwise.
    """
    basis = central_piola_basis(model, split, points)
    return None if basis is None else fit_step_squared(basis, D, K_o, "first-elasticity")


def central_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force right, nothing named) with central differences of P in F named first,
    partly explaining, when they fit; unchanged otherwise.
    """
    from conformance.diagnosis.elements import case_split
    from conformance.diagnosis.findings import PARTIAL, Finding, named_first

    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    K_o = sp.csr_matrix(ref.stiffness)
    with np.errstate(all="ignore"):
        fit = central_piola_fit(
            ci.model, split, ci.points, (sp.csr_matrix(out.stiffness) - K_o).tocsr(), K_o
        )
    if fit is None:
        return diag
    return named_first(
        diag,
        [
            Finding(
                "first-elasticity-finite-difference",
                "a finite-difference first elasticity tangent: central differences of the first "
                "Piola stress P in each component of F, (P(F + h e_l e_L) - P(F - h e_l e_L)) / "
                f"(2 h), step h = {fit.step:.2e}",
                PARTIAL,
                "K - K_oracle is that scheme's error per unit h^2 (measured by simulating it with "
                f"h = {PROBE:g} against the oracle's exact dP/dF), fitted with one unknown h^2: "
                f"it accounts for {100 * fit.explained:.2f} % of the stiffness error (left: "
                f"{fit.residual:.1e}, the higher orders and round-off); the force matches",
                {"step": fit.step, "scheme": fit.scheme, "explained": fit.explained},
            )
        ],
    )
