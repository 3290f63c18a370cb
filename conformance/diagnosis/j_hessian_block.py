"""MJED's J-Hessian block of the stiffness written with a wrong factor.

MJED's stiffness holds, per cell, the block f'(J) g(C) d2J/dx2 summed over the terms f(J) g(C),
with d2J/dx_a dx_b = (dJ_a dJ_b^T - dJ_b dJ_a^T) / J: the partial derivative psi_J of W in J,
the invariants of C (I1, I2) held, times the Hessian of J. An engine that writes this
antisymmetric block by hand may flip its sign (dJ_b dJ_a^T - dJ_a dJ_b^T), leave it out, or add
it twice; the force is untouched, and the stiffness error is, exactly, k psi_J V0 d2J/dx2 per
cell with k = -2, -1 or +1.

psi_J is taken from the oracle's declared energy (:func:`conformance.diagnosis.variants.
energy_expression`), by complex step in each invariant it reads and the chain rule to (I1, I2,
J): psi_J = W_J + W_I1b dI1b/dJ + W_I2b dI2b/dJ + W_I3 dI3/dJ. Each factor's prediction is
compared with the engine; named only within the case's tolerance. A material without a scalar
formula (Ogden, Costa) is not read.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Optional

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_gradients import invariant_slopes, j_hessian_tensor
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["FACTORS", "psi_j", "j_hessian", "j_hessian_findings", "j_hessian_reading"]

#: engine minus oracle, in units of the right block -> words.
FACTORS: Dict[float, str] = {
    -2.0: "with its sign flipped ((dJ_j dJ_i^T - dJ_i dJ_j^T) / J for "
    "(dJ_i dJ_j^T - dJ_j dJ_i^T) / J)",
    # the same stiffness, in the words of an engine that writes dP/dF in closed form: the
    # f'(J) g d2J/dx2 block is the antisymmetric part of f' g d(J F^-T)/dF, which cancels when
    # d(F^-T)_iJ/dF_kL = -F^-1_Jk F^-1_Li is typed with the other pairing, -F^-1_Ji F^-1_Lk
    -1.0: "left out (in a hand-written dP/dF: the derivative of F^-T, d(F^-T)_iJ/dF_kL = "
    "-F^-1_Jk F^-1_Li, written with its indices paired -F^-1_Ji F^-1_Lk, i.e. as -F^-T (x) "
    "F^-T: the same stiffness)",
    1.0: "added twice",
}


def psi_j(model: Any, F: np.ndarray) -> Optional[np.ndarray]:
    """(m,) dW/dJ with I1 and I2 held, at deformation gradients F (m, 3, 3), from the declared
    energy (complex step in the invariants it reads, the chain rule to I1, I2, J); None when it
    has no scalar formula of these invariants.
    """
    slopes = invariant_slopes(model, F, "I1, I2, J")
    return None if slopes is None else slopes[2]


def j_hessian(points: np.ndarray, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(m, 12, 12): V0 d2J/dx2 per cell, J (g_a g_b^T - g_b g_a^T) with g_a = F^-T D_a."""
    V0, D, F = cell_kinematics(points, cells, x)
    J = np.linalg.det(F)
    g = np.einsum("mji,maj->mai", np.linalg.inv(F), D)
    H = np.einsum("mai,mbj->maibj", g, g) - np.einsum("mbi,maj->maibj", g, g)
    return ((V0 * J)[:, None, None, None, None] * H).reshape(-1, 12, 12)


def j_hessian_findings(
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
    """The factors whose J-Hessian block error, added to the oracle's K (3n, 3n), matches the
    engine's K, the force f (n, 3) matching the oracle's.
    """
    K_o = sp.csr_matrix(K_o)
    if not tol.within(errors(f, K_o, None, f_o, K_o, 0.0, s), energy=False):
        return []
    _, _, F = cell_kinematics(points, cells, x)
    pj = psi_j(model, F)
    if pj is None or not np.any(pj):
        return []
    m, n = cells.shape[0], points.shape[0]
    block = assemble(
        cells, n, np.zeros((m, 4, 3)), pj[:, None, None] * j_hessian(points, cells, x)
    )[1]
    found = []
    for k, words in FACTORS.items():
        e = errors(f, K, None, f_o, K_o + k * block, 0.0, s)
        if not tol.within(e, energy=False):
            continue
        found.append(
            Finding(
                "j-hessian-block",
                "MJED stiffness: the J-Hessian block f'(J) g (dJ_i dJ_j^T - dJ_j dJ_i^T) / J "
                f"(psi_J d2J/dx2) {words}",
                FULL,
                f"the oracle's K plus {k:+g} x sum over cells of psi_J V0 d2J/dx2 (psi_J = dW/dJ "
                "with I1 and I2 held, from the oracle's energy; median "
                f"{float(np.median(pj)):.4g} Pa) matches the engine's K to {e.stiffness:.1e}; the "
                "force matches",
                {"factor": k, "stiffness_error": e.stiffness},
            )
        )
    if not found:
        found = _from_rows(points, cells, x, pj, f, K, f_o, K_o, s, tol)
    return ambiguous(found)


def _from_rows(points, cells, x, pj, f, K, f_o, K_o, s, tol) -> List[Finding]:
    """The Hessian of J built from the cross-product matrices of F's rows where its columns
    belong (d2J/dF2 at F^T, in the same layout: a row-major engine's form in a column-major
    one's), scaled by psi_J, with either sign; [] when neither matches.
    """
    from conformance.diagnosis.elements import tangent_element_matrices

    V0, D, F = cell_kinematics(points, cells, x)
    dA = pj[:, None, None, None, None] * (j_hessian_tensor(F.swapaxes(1, 2)) - j_hessian_tensor(F))
    m, n = cells.shape[0], points.shape[0]
    change = assemble(cells, n, np.zeros((m, 4, 3)), tangent_element_matrices(V0, D, dA))[1]
    if not change.nnz or sparse_norm(change) <= tol.stiffness * s.stiffness:
        return []  # F symmetric here: the rows are the columns
    e = errors(f, K, None, f_o, K_o + change, 0.0, s)
    if not tol.within(e, energy=False):
        return []
    return [
        Finding(
            "j-hessian-rows",
            "the Hessian of J = det F built from the cross-product matrices of F's rows where "
            "its columns belong (d2J/dF2 = eps_klm eps_ILM F_mM taken at F^T: a row-major "
            "layout's blocks in a column-major one), in the psi_J d2J/dF2 term of the tangent",
            FULL,
            f"the oracle's K plus sum over cells of psi_J V0 D . (d2J/dF2(F^T) - d2J/dF2(F)) . D "
            "(psi_J = dW/dJ with I1 and I2 held, from the oracle's energy) matches the engine's "
            f"K to {e.stiffness:.1e}; the force matches; where F is symmetric it changes nothing",
            {"stiffness_error": e.stiffness},
        )
    ]


def j_hessian_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing explaining the stiffness) with the J-Hessian block's
    factor named first when it explains the engine's K; unchanged otherwise.
    """
    found = j_hessian_findings(
        ci.model,
        ci.points,
        ci.cells,
        ci.positions,
        out.force,
        out.stiffness,
        ref.force,
        ref.stiffness,
        s,
        diag.tolerances,
    )
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
