"""The curvature of the isochoric factor J^p written wrongly in the tangent, the force right.

The isochoric invariants are I1b = J^p I1 (p = -2/3) and I2b = J^p I2 (p = -4/3). Their second
derivative holds I p (p - 1) J^(p - 2) dJ (x) dJ, the curvature of the power J^p. Engines get that
coefficient wrong where they differentiate the power themselves: a hand-derived tangent, or an
automatic-differentiation rule for x^p (dual or hyper-dual numbers) written with p^2, p, p (p + 1)
or the sign lost for p (p - 1), or the term left out. The first derivative p J^(p - 1) is not
touched, so the force stays right; the stiffness changes, cell by cell, by

    dK_c = V0 sum_k psi_k I_k (X(p_k) - p_k (p_k - 1)) J^(p_k - 2) dJ (x) dJ,

psi_k = dW/dIkb written from the energy's formula (:mod:`conformance.diagnosis.formula_derivative`)
and X the coefficient as written. A rule for the power is written once, so every isochoric
factor of the energy carries the same slip. Each slip predicts the engine's stiffness with
nothing fitted; it is named when that prediction is within the case's tolerance and the oracle's
own stiffness is not.
"""

from __future__ import annotations

from typing import Any, Callable, List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.derivative_rewrites import invariant_gradients, invariants, read_case
from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.formula_derivative import derivative
from conformance.diagnosis.variants import energy_expression
from conformance.judge.compare import Scales, Tolerances, errors
from reference_fem.user_energy import EnergySyntaxError, evaluate_formula

__all__ = ["SLIPS", "ISOCHORIC", "isochoric_curvature_findings", "isochoric_curvature_reading"]

#: isochoric invariant -> (its invariant, the power p of J in it)
ISOCHORIC = {"I1b": ("I1", -2.0 / 3.0), "I2b": ("I2", -4.0 / 3.0)}

#: (code, words, X(p)): the coefficient of J^(p - 2) as written where p (p - 1) belongs.
SLIPS: Tuple[Tuple[str, str, Callable[[float], float]], ...] = (
    ("p-squared", "p^2 J^(p-2) (p (p - 1) written p^2)", lambda p: p * p),
    ("first-derivative", "p J^(p-2) (the first derivative's p kept)", lambda p: p),
    ("p-plus-one", "p (p + 1) J^(p-2) (p - 1 written p + 1)", lambda p: p * (p + 1.0)),
    ("sign", "-p (p - 1) J^(p-2) (its sign flipped)", lambda p: -p * (p - 1.0)),
    ("dropped", "0 (the curvature of J^p left out)", lambda p: 0.0),
    ("halved", "p (p - 1) J^(p-2) / 2 (halved)", lambda p: p * (p - 1.0) / 2.0),
    ("doubled", "2 p (p - 1) J^(p-2) (doubled)", lambda p: 2.0 * p * (p - 1.0)),
)


def _cell_terms(model: Any, F: np.ndarray):
    """[(isochoric name, p, psi_k I_k J^(p - 2) per cell (m,))] for the energy's isochoric
    invariants; [] without a formula or without them.
    """
    base = energy_expression(model)
    if base is None:
        return []
    expression, params = base
    values = {**params, **invariants(F)}
    terms = []
    for name, (plain, p) in ISOCHORIC.items():
        try:
            written = derivative(expression, name)
        except (ValueError, SyntaxError):
            return []
        if written == "0":
            continue
        try:
            with np.errstate(all="ignore"):
                psi = np.broadcast_to(evaluate_formula(written, values), F.shape[:1])
        except (EnergySyntaxError, KeyError):
            return []  # a variable that is not a scalar invariant (C or E entries, I4)
        terms.append((name, p, psi * values[plain] * values["J"] ** (p - 2.0)))
    return terms


def isochoric_curvature_findings(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The slips of :data:`SLIPS` whose stiffness matches the engine's K (the force f (n, 3)
    judged too) where the oracle's K_o does not; several: ambiguous.
    """
    V0, D, F = cell_kinematics(points, cells, x)
    terms = _cell_terms(model, F)
    if not terms:
        return []
    K, K_o = sp.csr_matrix(K), sp.csr_matrix(K_o)
    gJ = invariant_gradients(F, invariants(F))["J"]
    G = np.einsum("miI,maI->mai", gJ, D).reshape(-1, 12)  # dJ/dx over each cell's 12 dofs
    outer = V0[:, None, None] * np.einsum("ma,mb->mab", G, G)
    zero = np.zeros((cells.shape[0], 4, 3))
    found = []
    for code, words, X in SLIPS:
        lam = sum(t * (X(p) - p * (p - 1.0)) for _, p, t in terms)
        if not np.all(np.isfinite(lam)):
            continue
        K_p = K_o + assemble(cells, points.shape[0], zero, lam[:, None, None] * outer)[1]
        if tol.within(errors(f_o, K_p, None, f_o, K_o, 0.0, s), energy=False):
            continue  # too small to see here
        e = errors(f, K, None, f_o, K_p, 0.0, s)
        if tol.within(e, energy=False):
            names = " and ".join(f"{n} = J^({_frac(p)}) {ISOCHORIC[n][0]}" for n, p, _ in terms)
            found.append(
                Finding(
                    f"isochoric-curvature-{code}",
                    "the second derivative of the isochoric factor J^p written "
                    f"{words} where p (p - 1) J^(p-2) belongs, in {names}: the tangent alone "
                    "(a slip in the power rule of a hand-derived or automatic-differentiation "
                    "tangent)",
                    FULL,
                    "the oracle's stiffness plus, per cell, V0 sum_k dW/dIkb Ik (X(p) - p (p - 1)) "
                    "J^(p-2) dJ (x) dJ with that coefficient X, nothing fitted: force error "
                    f"{e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"slip": code, "residual": max(e.force, e.stiffness)},
                )
            )
    return ambiguous(found)


def _frac(p: float) -> str:
    return {-2.0 / 3.0: "-2/3", -4.0 / 3.0: "-4/3"}.get(p, f"{p:g}")


def isochoric_curvature_reading(diag: Any, ci: Any, out: Any, ref: Any, s: Scales) -> Any:
    """``diag`` (a failed case, its force right, nothing named) with a slip in the curvature of
    J^p named first when one explains the stiffness; unchanged otherwise.
    """
    return read_case(isochoric_curvature_findings, diag, ci, out, ref, s)
