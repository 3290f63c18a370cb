"""One part of the energy off by a power of J per cell: a power of J in that part's value typed
with another exponent while the rest of its derivatives is right.

An engine that writes ``I1b = J ** (-2 // 3) * I1`` (Python's floor division makes the exponent
-1) and keeps ``-2/3`` in the chain-rule coefficients of ``dI1b/dJ`` computes, for a term linear
in I1b, the right stress and tangent multiplied in each cell by ``J^(-1/3)``: the wrong power
is a common factor of the value and of every derivative written from it. Its error is not
a coefficient (the factor changes from cell to cell) and not the derivative of another energy
(the factor is not differentiated): no energy hypothesis fits it.

For each parameter ``p`` that the energy is linear in, the oracle's element forces and matrices
split into the part proportional to ``p`` and the rest
(:func:`conformance.diagnosis.part_scalars.parameter_parts`). Here:

- one factor per cell, ``1 + lambda_e``, fitted to the stiffness error alone, predicts the force
  error too (:func:`conformance.diagnosis.part_scalars.fit_part_scale`);
- that factor is ``J_e^q`` for one exponent ``q`` over every cell: ``q`` is fitted on
  ``ln(1 + lambda_e) = q ln J_e`` and the force and stiffness *predicted* with ``J^q`` (no
  factor per cell left free) must match the engine's within the tolerances;
- J differs between the cells (on a homogeneous state the factor is one number, which a
  coefficient fits as well; :func:`conformance.diagnosis.corroborate.extend_covered` gives such
  a case this cause where its factor is ``J^q`` at its J).

NumPy and MJED only.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any, List

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, element_split
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.diagnosis.part_scalars import fit_part_scale, parameter_parts
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["SPREAD", "part_power_findings", "part_power_reading", "exponent_text"]

#: The cells' ln J must spread by at least this for an exponent to be read (about 1 %).
SPREAD = 1e-2

#: An exponent this close to zero is no factor at all.
_SMALLEST_EXPONENT = 1e-3


def exponent_text(q: float) -> str:
    """``q`` as a fraction with a small denominator where it is one to 1e-6 ("-1/3"), else in
    decimals.
    """
    frac = Fraction(q).limit_denominator(12)
    if abs(float(frac) - q) <= 1e-6 * max(1.0, abs(q)):
        return str(frac)
    return f"{q:.6g}"


def _part_label(model: Any, name: str) -> str:
    """The declared formula of the energy's term in ``name`` alone, else the parameter's name."""
    from conformance.diagnosis.energy_terms import term_names
    from conformance.diagnosis.term_fit import term_labels

    try:
        labels, names = term_labels(model), term_names(model)
    except Exception:  # noqa: BLE001 - a formula the split cannot read: the parameter's name
        return f"the part in {name}"
    for label, text in zip(labels, names):
        if tuple(label) == (name,) and text:
            return text
    return f"the part in {name}"


def part_power_findings(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    out,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The findings naming one parameter's part scaled per cell by a power of J (several:
    ambiguous), or [] without the evidence of the module's docstring. out: the engine's output;
    f_o, K_o: the oracle's.
    """
    lnJ = np.log(np.abs(np.linalg.det(split.F)))
    if not np.all(np.isfinite(lnJ)) or np.ptp(lnJ) < SPREAD:
        return []
    parts = parameter_parts(model, points, split.cells, positions, split)
    found = []
    for name, part in parts.items():
        e, lam = fit_part_scale(split, part, out.force, out.stiffness, f_o, K_o, s)
        if not tol.within(e, energy=False) or np.any(1.0 + lam <= 0.0):
            continue
        y = np.log1p(lam)
        q = float(lnJ @ y / (lnJ @ lnJ))
        if abs(q) < _SMALLEST_EXPONENT:
            continue
        # predicted: the factor J^q in every cell, nothing fitted per cell
        mu = np.expm1(q * lnJ)
        fe_p, Ke_p = part
        df, dK = assemble(split.cells, split.n, mu[:, None, None] * fe_p, mu[:, None, None] * Ke_p)
        p = errors(out.force, out.stiffness, None, f_o + df, sp.csr_matrix(K_o) + dK, 0.0, s)
        if not tol.within(p, energy=False):
            continue
        text = exponent_text(q)
        label = _part_label(model, name)
        # the one slip that gives -1/3 by itself: an isochoric J^(-2/3) typed with floor division
        example = ", e.g. J^(-1) for J^(-2/3), as Python's -2 // 3 gives" if text == "-1/3" else ""
        found.append(
            Finding(
                "part-power-of-j",
                f"{label}: its force and stiffness multiplied in each cell by J^({text}), a power "
                f"of J in that part's value typed with another exponent{example}, while the "
                "other factors of its derivatives are right",
                FULL,
                f"per cell, your stiffness error is lambda times the part of the oracle's element "
                f"matrix proportional to {name} (lambda fitted, one per cell; the same lambda "
                f"predicts your force error: errors {e.force:.1e}, {e.stiffness:.1e} after it); "
                f"1 + lambda = J^q over the {lnJ.size} cells (J from {np.exp(lnJ.min()):.4g} to "
                f"{np.exp(lnJ.max()):.4g}) with q = {q:.6g}, and J^q alone, nothing fitted per "
                f"cell, predicts your force and stiffness to {p.force:.1e} and {p.stiffness:.1e}; "
                "a factor that is not differentiated is not another energy's derivative",
                {
                    "parameter": name,
                    "exponent": q,
                    "residual": float(max(p.force, p.stiffness)),
                    # a homogeneous state fits the factor at its one J as this part's
                    # coefficient (corroborate.extend_covered)
                    "covers": ["term-coefficients"],
                },
            )
        )
    return ambiguous(found) if len(found) > 1 else found


def part_power_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with a part of the energy scaled per cell by
    a power of J named first; unchanged when none is or MJED does not split this case.
    """
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, diag.tolerances
    )
    if split is None:
        return diag
    with np.errstate(all="ignore"):
        found = part_power_findings(
            split, ci.model, ci.points, ci.positions, out, ref.force, ref.stiffness, s,
            diag.tolerances,
        )  # fmt: skip
    return named_first(diag, found)
