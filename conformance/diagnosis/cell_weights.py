"""Each cell's contribution weighted by a wrong geometric quantity of the cell.

An engine that writes its own volume weighting may weight every cell by the wrong quantity:
the rest volume V0 applied a second time (element matrices that already carry V0 multiplied by
it again), V0 left out (divided by it), or every cell given the mesh's mean rest volume (as on a
structured grid). The engine's output is then, exactly, the oracle's element forces and
matrices (MJED's, used only where their sum is the oracle's:
:func:`conformance.diagnosis.elements.element_split`) summed with per-cell weights q_c / 1 that
are that quantity over the right one: V0_c, 1 / V0_c, mean(V0) / V0_c. Force and stiffness are
tested separately (an engine may weight one and not the other). No fit: each candidate's
weights are fixed, and one is named only when its sum matches the engine within tolerance.
A mesh whose cells all have the same volume cannot tell these from a global factor, which the
global readings name; no candidate is tried there.

Beside the fixed weights, the rest volume computed as another power of V0 times a constant
(:data:`POWERS`): the volume from the stored inverse edge matrix, |det(Dm^-1)| / 6 = 1 / (36 V0),
where |det Dm| / 6 belongs, weights every cell by 1 / (36 V0^2). The power is declared, the one
constant fitted (least squares on the part that is wrong), and the constant said with the formula
it matches when it is one of :data:`CONSTANTS`.

The same weights on one part of the element matrix alone, the force and the other part right:
the geometric part V0 (D_a . S D_b) I3 (S read back from the element forces) or the material part
(the rest), as in V0 B^T D B + K_geo where V0 (B^T D B + K_geo) belongs.

Last, any other per-cell factor (a volume computed by a formula with a typo, a cell's volume of
the wrong sign, a coefficient that differs from cell to cell): one weight per cell fitted by
least squares to force and stiffness together (:func:`fitted_weight_findings`: the all-cells fit
of :mod:`conformance.diagnosis.cells` read as weights), named only when the fitted sum matches
the engine within tolerance, the system has at least :data:`OVERDETERMINED` equations per
weight, and the weights are not all alike (a global factor, which the global readings name) nor
all whole numbers (cells skipped or counted again, which :mod:`conformance.diagnosis.cells`
names cell by cell).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Dict, List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    element_split,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.hypotheses import fit_scale
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "WEIGHTS",
    "POWERS",
    "CONSTANTS",
    "cell_weight_findings",
    "cell_weight_reading",
    "fitted_weight_findings",
    "stiffness_parts",
]

#: name -> (words, weights (m,) from the rest volumes V0 (m,)).
WEIGHTS: Dict[str, Tuple[str, Callable[[np.ndarray], np.ndarray]]] = {
    "V0 twice": (
        "multiplied by the cell's rest volume V0 twice (a matrix that already carries V0 "
        "scaled by it again): each cell weighted by V0^2",
        lambda V0: V0,
    ),
    "V0 missing": (
        "not multiplied by the cell's rest volume V0 (a density summed as if it were the "
        "cell's contribution)",
        lambda V0: 1.0 / V0,
    ),
    "mean volume": (
        "weighted by the mesh's mean rest volume (total volume / number of cells, as on a "
        "structured grid) instead of each cell's own V0",
        lambda V0: np.full_like(V0, V0.mean()) / V0,
    ),
}

#: power p -> words: the engine's volume is c V0^p (c a constant), each cell weighted by c V0^(p-1).
POWERS: Dict[int, str] = {
    -1: "computed as a constant over the right one (the volume of the inverse edge matrix Dm^-1, "
    "proportional to 1 / V0)",
    2: "proportional to V0^2 (the volume multiplied in twice, with a constant)",
}

#: (power, constant c) -> the formula of the engine's volume c V0^p said by name.
CONSTANTS: Dict[Tuple[int, float], str] = {
    (-1, 1 / 36): "|det(Dm^-1)| / 6 = 1 / (36 V0), from the stored inverse Dm^-1, where "
    "V0 = |det Dm| / 6 belongs",
    (-1, 1 / 6): "|det(Dm^-1)| = 1 / (6 V0), from the stored inverse Dm^-1 (and without the "
    "1/6), where V0 = |det Dm| / 6 belongs",
    (-1, 1.0): "1 / V0 (the volume inverted)",
    (2, 6.0): "V0 |det Dm| = 6 V0^2 (V0 applied twice, once without the 1/6)",
    (2, 36.0): "(det Dm)^2 = 36 V0^2",
}

#: Spread of the rest volumes (max / min - 1) below which the cells are alike: no reading.
ALIKE = 1e-6

#: Equations (force entries and stiffness entries) per fitted weight, at least.
OVERDETERMINED = 4


def cell_weight_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The weightings (of the force, the stiffness or both) whose sums of the oracle's element
    forces (m, 4, 3) and matrices (m, 12, 12) match the engine's f (n, 3) and K (3n, 3n).
    """
    V0 = split.V0
    if V0.max() <= V0.min() * (1 + ALIKE):
        return ambiguous(_part_j_findings(split, f, K, f_o, K_o, s, tol))
    K = sp.csr_matrix(K)
    found = []
    for name, (words, weight) in WEIGHTS.items():
        q = weight(V0)
        f_q, K_q = assemble(
            split.cells, split.n, q[:, None, None] * split.fe, q[:, None, None] * split.Ke
        )
        for which, f_pred, K_pred in (
            ("force and stiffness", f_q, K_q),
            ("stiffness", f_o, K_q),
            ("force", f_q, K_o),
        ):
            e = errors(f, K, None, f_pred, K_pred, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            found.append(
                Finding(
                    "cell-weight",
                    f"each cell's {which} {words}",
                    FULL,
                    "the oracle's element forces and matrices (MJED's, whose sum is the "
                    f"oracle's to {split.residual:.1e}) summed with those weights (rest volumes "
                    f"from {V0.min():.3g} to {V0.max():.3g} m^3) match the engine: force error "
                    f"{e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"weighting": name, "applies_to": which, "residual": max(e.force, e.stiffness)},
                )
            )
    found = found or _part_weight_findings(split, f, K, f_o, K_o, s, tol)
    found = found or _part_j_findings(split, f, K, f_o, K_o, s, tol)
    found = found or _power_findings(split, f, K, f_o, K_o, s, tol)
    found = found or fitted_weight_findings(split, f, K, f_o, K_o, s, tol)
    return ambiguous(found, "the weightings coincide on this mesh")


def stiffness_parts(split: ElementSplit) -> Dict[str, np.ndarray]:
    """The oracle's element matrices split into the geometric part V0 (D_a . S D_b) I3 and the
    material part (the rest), each (m, 12, 12); S per cell from the element forces.
    """
    P, _ = cell_piola(split)
    S = np.linalg.solve(split.F, P)  # P = F S
    A = np.einsum("kl,mIL->mkIlL", np.eye(3), S)
    geo = tangent_element_matrices(split.V0, split.D, A)
    return {"geometric stiffness": geo, "material stiffness": split.Ke - geo}


def _part_weight_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """One part of the element matrix (geometric or material) weighted wrongly, the other and
    the force right: V0 left out of the geometric part in V0 B^T D B + K_geo (the parentheses of
    V0 (B^T D B + K_geo) lost), or applied twice to one part (:data:`WEIGHTS`).
    """
    V0 = split.V0
    how = f"summed with those weights (rest volumes from {V0.min():.3g} to {V0.max():.3g} m^3)"
    weights = {name: (words, weight(V0), how) for name, (words, weight) in WEIGHTS.items()}
    return _weighted_part_findings(split, f, K, f_o, K_o, s, tol, weights)


#: name -> (words, weights (m,) from each cell's J): one part of the element matrix integrated
#: over the other configuration's volume (a spatial engine's v = J V0 where V0 belongs, or back).
J_WEIGHTS: Dict[str, Tuple[str, Callable[[np.ndarray], np.ndarray]]] = {
    "rest volume": (
        "integrated over the rest volume V0 where the deformed volume v = J V0 belongs (the J "
        "of v lost in that part)",
        lambda J: 1.0 / J,
    ),
    "deformed volume": (
        "integrated over the deformed volume v = J V0 where the rest volume V0 belongs (a J "
        "too many in that part)",
        lambda J: J,
    ),
}


def _part_j_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """One part of the element matrix (geometric or material) integrated over the wrong
    configuration's volume (:data:`J_WEIGHTS`), the other part and the force right: each cell's
    part times 1/J or J, nothing fitted. Where every cell has the same J this is a factor of
    that part, which the tangent-part readings name; tried all the same (the words say both).
    """
    J = np.linalg.det(split.F)
    one_j = np.ptp(J) <= 1e-9 * np.abs(J).max()
    weights = {}
    for name, (words, weight) in J_WEIGHTS.items():
        how = f"times each cell's {'1/J' if name == 'rest volume' else 'J'}"
        if one_j:
            how += (
                f" (every cell has J = {J[0]:.6g} here: equally that part times {weight(J)[0]:.6g})"
            )
        weights[name] = (words, weight(J), how)
    return _weighted_part_findings(split, f, K, f_o, K_o, s, tol, weights)


def _weighted_part_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
    weights: Dict[str, Tuple[str, np.ndarray, str]],
) -> List[Finding]:
    """Each part of the element matrix (:func:`stiffness_parts`) summed with each of
    ``weights`` (name -> (words, per-cell weight (m,), how it was weighted, in words)), the
    other part and the force right: those that match the engine.
    """
    if errors(f, K_o, None, f_o, K_o, 0.0, s).force > tol.force:
        return []
    found = []
    for part, Ke in stiffness_parts(split).items():
        for name, (words, weight, how) in weights.items():
            q = weight - 1.0
            _, dK = assemble(split.cells, split.n, np.zeros_like(split.fe), q[:, None, None] * Ke)
            e = errors(f, K, None, f_o, sp.csr_matrix(K_o) + dK, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            found.append(
                Finding(
                    "cell-weight",
                    f"each cell's {part} (that part of the element matrix alone) {words}",
                    FULL,
                    "the oracle's element matrices split into the geometric part V0 (D_a . S "
                    f"D_b) I and the material part, that part {how}, match the engine: force "
                    f"error {e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"weighting": name, "applies_to": part, "residual": max(e.force, e.stiffness)},
                )
            )
    return found


def fitted_weight_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """One weight per cell, fitted: the engine's f (n, 3) and K (3n, 3n) as sum_c w_c (f_c, K_c)
    of the oracle's element forces and matrices, w = 1 + the coefficients of
    :func:`conformance.diagnosis.cells.fit_all_cells` (engine - oracle over every cell); a
    finding when that sum matches within tolerance and the weights differ from cell to cell.
    """
    from conformance.diagnosis.cells import fit_all_cells

    m, n = split.cells.shape[0], split.n
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    touched = np.unique((np.repeat(dof, 12, axis=1) * (3 * n) + np.tile(dof, (1, 12))).ravel())
    n_eq = 3 * n + touched.size  # force entries and the stiffness entries the cells reach
    if n_eq < OVERDETERMINED * m or not (s.force > 0 and s.stiffness > 0):
        return []
    K = sp.csr_matrix(K)
    fit = fit_all_cells(split.cells, n, split.fe, split.Ke, np.asarray(f) - f_o, K - K_o, s)
    if fit is None:
        return []
    w = 1.0 + fit.alpha
    if not np.isfinite(w).all() or np.ptp(w) <= 1e-6 * np.abs(w).max():
        return []
    if np.abs(w - np.round(w)).max() <= 1e-6:  # cells left out or repeated: said by cells.py
        return []
    f_w, K_w = assemble(split.cells, n, w[:, None, None] * split.fe, w[:, None, None] * split.Ke)
    e = errors(f, K, None, f_w, K_w, 0.0, s)
    if not tol.within(e, energy=False):
        return []
    off = int(np.sum(np.abs(w - 1.0) > 1e-6))
    return [
        Finding(
            "cell-weight",
            "each cell's contribution scaled by a factor of its own: a per-cell quantity wrong, "
            f"such as the cell's rest volume V0 computed wrongly ({off} of {m} cells off, "
            f"factors from {w.min():.4g} to {w.max():.4g})",
            FULL,
            "the oracle's element forces and matrices (MJED's, whose sum is the oracle's to "
            f"{split.residual:.1e}) summed with one weight per cell, fitted (least squares, "
            f"{n_eq} equations for {m} weights), match the engine: force error {e.force:.1e}, "
            f"stiffness error {e.stiffness:.1e}",
            {
                "weighting": "fitted per cell",
                "applies_to": "force and stiffness",
                "cells_off": off,
                "residual": max(e.force, e.stiffness),
            },
        )
    ]


def _constant_words(p: int, c: float) -> str:
    """The engine's volume c V0^p by name, or with the fitted constant."""
    for (q, known), words in CONSTANTS.items():
        if q == p and abs(c - known) <= 1e-6 * known:
            return words
    return f"{c:.6g} V0^{p}"


def _power_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.csr_matrix,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The powers of :data:`POWERS` whose weights c V0^(p-1), c fitted on the part that is
    wrong, match the engine (force, stiffness or both).
    """
    V0 = split.V0
    found = []
    for p, words in POWERS.items():
        q = V0 ** (p - 1)
        f_q, K_q = assemble(
            split.cells, split.n, q[:, None, None] * split.fe, q[:, None, None] * split.Ke
        )
        c_f, c_K = fit_scale(f_q, f), fit_scale(K_q, K)
        for which, c, f_pred, K_pred in (
            ("force and stiffness", c_K, c_K * f_q, c_K * K_q),
            ("stiffness", c_K, f_o, c_K * K_q),
            ("force", c_f, c_f * f_q, K_o),
        ):
            if c is None or not np.isfinite(c) or c <= 0:
                continue
            e = errors(f, K, None, f_pred, K_pred, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            formula = _constant_words(p, c)
            found.append(
                Finding(
                    "cell-weight",
                    f"each cell's {which} weighted by a wrong rest volume, {formula}: the "
                    f"engine's volume {words}, so every cell's contribution scaled by "
                    f"{c:.6g} V0^{p - 1} (a per-cell factor)",
                    FULL,
                    "the oracle's element forces and matrices (MJED's, whose sum is the "
                    f"oracle's to {split.residual:.1e}) summed with weights c V0^{p - 1}, "
                    f"c = {c:.9g} fitted (rest volumes from {V0.min():.3g} to {V0.max():.3g} "
                    f"m^3), match the engine: force error {e.force:.1e}, stiffness error "
                    f"{e.stiffness:.1e}",
                    {
                        "weighting": f"V0^{p}",
                        "constant": c,
                        "applies_to": which,
                        "residual": max(e.force, e.stiffness),
                    },
                )
            )
            break
    return found


def cell_weight_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with a per-cell volume weighting named
    first when the engine's output is it; unchanged otherwise (or without an MJED split).
    """
    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    found = cell_weight_findings(split, out.force, out.stiffness, ref.force, ref.stiffness, s, tol)
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
