"""One part of the energy off by a factor per cell drawn at random: a scalar of that part (its
coefficient, an exponential, the exponential's argument) rounded to float32 inside a
double-precision engine.

An engine that computes ``a/2 exp(b (I1b - 3))`` with the argument held in float32 keeps every
tensor in double: no intermediate tensor is rounded (:mod:`conformance.diagnosis.mixed_precision`
finds no pattern), the balance laws hold, and the error, 1e-8 of the stress, is as small as a
slightly wrong constant's. Its signature is elsewhere. For every parameter ``p`` that the energy
is linear in, the oracle's element forces and matrices split into the part proportional to ``p``
(its derivative in ``p`` times ``p``, exact: the energy is linear in it) and the rest. Such an
engine's error is, cell by cell, one factor lambda_e times that part's element force *and*
matrix: the scalar multiplies both. So:

- lambda (one unknown per cell) is fitted to the stiffness error alone and must then predict the
  force error too, both within the double tolerance (a tangent-only or stress-only mistake, and
  most formula errors, fail one of the two);
- lambda is not a function of the cell's state: a least-squares fit on the components of C,
  J, I1b, I2b and their squares, cross-validated, predicts little of it (a formula error with a
  wrong constant gives a smooth lambda, predicted almost entirely), takes both signs about a
  mean near zero, and is of float32's size (float32 rounds a value by up to 2^-24 = 6e-8 of
  itself; an exponential's argument x rounded changes the exponential by up to 6e-8 x of
  itself);
- where the kit has probes, the force error is drawn anew at every probe x + h d, as rounding is
  and a smooth error is not (:func:`conformance.diagnosis.mixed_precision.noise`).

On a state where every cell is alike (a homogeneous stretch) lambda is one number, which a
parameter refit explains as well; the kit's other states tell them apart
(:func:`conformance.diagnosis.corroborate.extend_covered`). NumPy and MJED only.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, mjed_element_arrays
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.parameters import scaled_models
from conformance.diagnosis.second_derivative import fit_cell_term
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "UNIT_ROUNDOFF",
    "parameter_parts",
    "fit_part_scale",
    "explained_share",
    "part_scalar_findings",
]

#: float32's unit round-off, 2^-24.
UNIT_ROUNDOFF = 2.0**-24

#: The relative step at which a parameter's part is read off, and the check that the energy is
#: linear in it (a second step twice as long gives the same part to this relative accuracy).
_STEP = 1e-3
_LINEAR = 1e-8
_CANCEL = 1e-10

#: lambda of float32's size: at most this (a rounded argument of up to about 100 times 2^-24)...
LARGEST = 1e-5
#: ...and at least this (rms; below, there is nothing to read).
SMALLEST = 1e-10

#: The share of lambda's variance that smooth functions of the state may predict (a formula
#: error's lambda is predicted almost entirely; values drawn at random, about 0).
SMOOTH_SHARE = 0.3

#: Each sign taken by at least this share of the cells, and the mean at most this share of the
#: rms (rounding to nearest is unbiased; a constant error added to it is not rounding).
SIGN_SHARE = 0.1
MEAN_SHARE = 0.5

#: Without probes: the smallest number of cells of distinct state that show lambda unstructured.
UNPROBED_CELLS = 50


def parameter_parts(
    model: Any, points: np.ndarray, cells: np.ndarray, positions: np.ndarray, split: ElementSplit
) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """{parameter: (fe (m, 4, 3), Ke (m, 12, 12))}: for each scalar parameter of ``model``
    that its energy is linear in, the element forces and matrices of the part of the
    energy proportional to it (p dW/dp), read off MJED by a relative step and kept only where a
    step twice as long gives the same part (linear: exact to round-off). A parameter the model
    refuses to change, or that is zero, is left out.
    """
    parts: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}
    for name, changed in scaled_models(model, (1.0 + _STEP, 1.0 + 2.0 * _STEP)):
        steps = []
        for k, other in zip((1.0, 2.0), changed):
            arrays = mjed_element_arrays(other, points, cells, positions)
            if arrays is None or not all(np.all(np.isfinite(a)) for a in arrays):
                break
            steps.append(
                ((arrays[0] - split.fe) / (k * _STEP), (arrays[1] - split.Ke) / (k * _STEP))
            )
        if len(steps) < 2:
            continue
        (fe1, Ke1), (fe2, Ke2) = steps
        # linear: two steps agree to round-off, which the cancellation against the whole
        # (2^-52 of it over the step) bounds
        scale = np.linalg.norm(Ke1)
        if scale == 0.0 or np.linalg.norm(Ke2 - Ke1) > _LINEAR * scale + _CANCEL * np.linalg.norm(
            split.Ke
        ):
            continue
        if np.linalg.norm(fe2 - fe1) > _LINEAR * np.linalg.norm(fe1) + _CANCEL * np.linalg.norm(
            split.fe
        ):
            continue
        parts[name] = (fe1, Ke1)
    return parts


def fit_part_scale(
    split: ElementSplit,
    part: Tuple[np.ndarray, np.ndarray],
    out_force: np.ndarray,
    out_stiffness: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
):
    """(Errors after the fit, lambda (m,)): lambda fitted per cell to the stiffness error
    K - K_o as lambda_e times the part's element matrix (least squares), then the force and
    stiffness predicted as the oracle's plus lambda_e times the part's, and compared with the
    engine's.
    """
    fe_p, Ke_p = part
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(out_stiffness) - K_o).tocsr()
    _, lam = fit_cell_term(split.cells, Ke_p, D, K_o)
    df, dK = assemble(split.cells, split.n, lam[:, None, None] * fe_p, lam[:, None, None] * Ke_p)
    e = errors(out_force, out_stiffness, None, f_o + df, K_o + dK, 0.0, s)
    return e, lam


def _state_features(F: np.ndarray) -> np.ndarray:
    """(m, 13): 1, the six components of C, J, I1b, I2b and the squares of the last three: the
    smooth functions of a cell's state that a formula error's lambda follows.
    """
    from conformance.diagnosis.term_differences import cell_invariants

    C = np.einsum("mki,mkj->mij", F, F)
    inv = cell_invariants(F)
    J = inv["J"]
    iu = np.triu_indices(3)
    scalars = np.stack([J, inv["I1b"], inv["I2b"]], axis=1)
    return np.column_stack([np.ones_like(J), C[:, iu[0], iu[1]], scalars, scalars**2])


#: Folds of the cross-validated share (each cell predicted by a fit on the others' folds).
_FOLDS = 5


def explained_share(F: np.ndarray, lam: np.ndarray) -> float:
    """The share of lambda's variance that smooth functions of the cell's state
    (:func:`_state_features`) predict, cross-validated: each fifth of the cells predicted by a
    least-squares fit on the other four fifths. Near 1 for a smooth function of the state, near
    0 (or below) for values drawn at random per cell; a cell far from the others (a distorted
    sliver, whose rounded argument is large) cannot be fitted alone, as it could in-sample.
    """
    X = _state_features(F)
    X = X / np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    fold = np.arange(lam.size) % _FOLDS
    left = total = 0.0
    for k in range(_FOLDS):
        test, train = fold == k, fold != k
        if not test.any() or train.sum() <= X.shape[1]:
            return 1.0  # too few cells to tell: not shown unstructured
        coef, *_ = np.linalg.lstsq(X[train], lam[train], rcond=None)
        left += float(np.sum((lam[test] - X[test] @ coef) ** 2))
        total += float(np.sum((lam[test] - lam[train].mean()) ** 2))
    return 1.0 if total == 0.0 else 1.0 - left / total


def _distinct_cells(F: np.ndarray) -> int:
    C = np.einsum("mki,mkj->mij", F, F).reshape(-1, 9)
    return int(np.unique(np.round(C, 12), axis=0).shape[0])


def part_scalar_findings(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    out,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
    noisy: Optional[bool],
) -> List[Finding]:
    """The findings naming a scalar of one parameter's part rounded to float32 per cell (one
    per part that fits; several: ambiguous), or [] without the evidence of the module's
    docstring. out: the engine's output; f_o, K_o: the oracle's; noisy: whether the force error
    is drawn anew at the probes (None: the kit has none).
    """
    if noisy is False:
        return []
    parts = parameter_parts(model, points, split.cells, positions, split)
    distinct = _distinct_cells(split.F)
    if noisy is None and distinct < UNPROBED_CELLS:
        return []
    found = []
    for name, part in parts.items():
        e, lam = fit_part_scale(split, part, out.force, out.stiffness, f_o, K_o, s)
        if not tol.within(e, energy=False):
            continue
        rms = float(np.sqrt(np.mean(lam**2)))
        if not (SMALLEST <= rms and np.max(np.abs(lam)) <= LARGEST):
            continue
        share = explained_share(split.F, lam)
        positive = float(np.mean(lam > 0))
        if share > SMOOTH_SHARE or min(positive, 1.0 - positive) < SIGN_SHARE:
            continue
        if abs(float(lam.mean())) > MEAN_SHARE * rms:  # a constant's share: not rounding
            continue
        drawn = (
            "the force error is drawn anew at every probe x + h d, as rounding is and a smooth "
            "error is not"
            if noisy
            else f"over {distinct} cells of distinct state"
        )
        found.append(
            Finding(
                "single-precision-part-scalar",
                f"a scalar of the energy's part in {name} computed in single precision (float32) "
                "in your double-precision engine (its coefficient, an exponential or its "
                "argument rounded): that part's force and stiffness are off by a factor "
                "1 + lambda per cell, lambda of float32's size and drawn at random",
                FULL,
                f"per cell, your stiffness error is lambda times the part of the oracle's element "
                f"matrix proportional to {name} (lambda fitted, one per cell), and the same "
                f"lambda predicts your force error too: force error {e.force:.1e}, stiffness "
                f"error {e.stiffness:.1e} after it; lambda from {lam.min():+.2g} to "
                f"{lam.max():+.2g} (rms {rms:.2g}, {rms / UNIT_ROUNDOFF:.2g} times float32's "
                f"unit round-off; {positive:.0%} of the cells positive), not a function of the "
                f"cell's state (its components of C, J, I1b, I2b predict {max(share, 0.0):.0%} "
                "of it, cross-validated); "
                f"{drawn}",
                {
                    "parameter": name,
                    "rms": rms,
                    "largest": float(np.max(np.abs(lam))),
                    "explained_share": share,
                    "positive_share": positive,
                    "residual": float(max(e.force, e.stiffness)),
                    # a homogeneous state of the kit fits the same factor as this parameter
                    # changed by float32's size (corroborate.extend_covered)
                    "covers": ["parameter-value"],
                    "covers_relative": LARGEST,
                },
            )
        )
    return ambiguous(found) if len(found) > 1 else found
