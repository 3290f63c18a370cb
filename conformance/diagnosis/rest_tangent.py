"""The material tangent frozen at the rest state: a linear-elastic template's tangent.

An engine ported from a linear-elastic code (a UMAT template's DDSDDE = lam I (x) I + 2 mu II,
a small-strain element's D matrix) keeps the tangent of the undeformed material,
CC0 = CC(F = I), at every state, while its stress, force and initial-stress stiffness follow
the hyperelastic law. Its stiffness is then predicted with nothing fitted from the oracle's
own tangent at rest (its element split at the rest positions, where S = 0 and CC = c) and its
stress at the state, in three assemblies an engine may use:

- spatial: v (g_a . CC0 . g_b) + v (g_a . sigma g_b) I (CC0 taken as the Truesdell tangent);
- total Lagrangian: V0 D_a (delta S + F CC0 F^T) D_b (CC0 taken as dS/dE);
- spatial over the rest volume: V0 (g_a . CC0 . g_b) + v (g_a . sigma g_b) I.

Named when one matches the engine's stiffness within the tolerance, the force right.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    case_split,
    cell_piola,
    element_split,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.judge.compare import Scales, errors

__all__ = ["ASSEMBLIES", "rest_tangent_findings", "rest_tangent_reading"]

_EYE = np.eye(3)

#: assembly -> words.
ASSEMBLIES = {
    "spatial": "as the spatial tangent c, v (g_a . CC0 . g_b), beside the initial-stress part",
    "material": "as the material tangent dS/dE, V0 D_a (F CC0 F^T) D_b, beside V0 D_a S D_b I",
    "spatial-rest-volume": "as the spatial tangent over the rest volume, V0 (g_a . CC0 . g_b)",
}


def _stiffness(split: ElementSplit, S: np.ndarray, CC0: np.ndarray, how: str) -> np.ndarray:
    """(m, 12, 12) element stiffness of the frozen tangent CC0 (m, 3, 3, 3, 3) at the split's
    state, stress S (m, 3, 3), assembled ``how`` (:data:`ASSEMBLIES`).
    """
    F, D, V0 = split.F, split.D, split.V0
    J = np.linalg.det(F)
    P = F @ S
    sigma = P @ F.swapaxes(1, 2) / J[:, None, None]
    g = D @ np.linalg.inv(F)
    if how == "material":
        A = np.einsum("miI,mIJKL,mkK->miJkL", F, CC0, F)  # A_iJkL = F_iI CC_IJKL F_kK
        Ke = np.einsum("m,maJ,miJkL,mbL->maibk", V0, D, A, D)
        Ke = Ke + np.einsum("m,maI,mIJ,mbJ,ik->maibk", V0, D, S, D, _EYE)
        return Ke.reshape(-1, 12, 12)
    w = V0 * J if how == "spatial" else V0
    Ke = np.einsum("m,maj,mkjlq,mbq->makbl", w, g, CC0, g)
    Ke = Ke + np.einsum("m,mai,mij,mbj,kl->makbl", V0 * J, g, sigma, g, _EYE)
    return Ke.reshape(-1, 12, 12)


def rest_tangent_findings(split: ElementSplit, rest: ElementSplit, f, K, s: Scales, tol):
    """The assemblies of :data:`ASSEMBLIES` whose stiffness with the rest split's tangent
    (``rest``: the oracle's element split at the rest positions) matches the engine's, the
    force right and the oracle's own stiffness not matched; [] otherwise.
    """
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    e = errors(f, K, None, f0, K0, 0.0, s)
    if e.force > tol.force or e.stiffness <= tol.stiffness:
        return []
    t = cell_tensors(*cell_piola(split), split.F)
    CC0 = cell_tensors(*cell_piola(rest), rest.F).CC
    found = []
    for how, words in ASSEMBLIES.items():
        _, Kp = assemble(split.cells, split.n, split.fe, _stiffness(split, t.S, CC0, how))
        left = errors(f, K, None, f0, Kp, 0.0, s)
        if left.stiffness > tol.stiffness:
            continue
        found.append(
            Finding(
                "rest-tangent",
                "your tangent is the material's tangent at rest, CC0 = CC(F = I), at every "
                f"state (a linear-elastic template's tangent, e.g. lam I (x) I + 2 mu II, kept "
                f"where the law's own belongs), assembled {words}",
                FULL,
                "the oracle's tangent at the rest positions, per cell, with the oracle's stress "
                f"at this state, nothing fitted: stiffness error against your engine "
                f"{left.stiffness:.1e}; the force matches",
                {"assembly": how, "residual": left.stiffness},
            )
        )
    return ambiguous(found)


def rest_tangent_reading(diag, cache, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing named) with a tangent frozen at rest named first;
    unchanged when none matches or the oracle's split at rest does not add up.
    """
    tol = diag.tolerances
    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    at_rest = replace(ci, positions=np.array(ci.points, dtype=np.float64))
    try:
        r = cache.reference(at_rest)
    except ValueError:  # the oracle cannot evaluate the rest state
        return diag
    rest = element_split(
        ci.model, ci.points, ci.cells, at_rest.positions, r.force, r.stiffness, s, tol
    )
    if rest is None:
        return diag
    with np.errstate(all="ignore"):
        found = rest_tangent_findings(split, rest, out.force, out.stiffness, s, tol)
    if not found:
        return diag
    kept = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*found, *kept])
