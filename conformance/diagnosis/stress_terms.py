"""A hand-written stress with B where C belongs (or B^-1 where C^-1 belongs) in one of its terms.

An isotropic second Piola-Kirchhoff stress is S = phi0 I + phi1 C + phi2 C^-1, each phi a
function of the invariants. An engine that writes S by hand and uses B = F F^T for C in the
phi1 term (or B^-1 for C^-1 in the phi2 term) computes P' = F (S + beta (X(B) - X(C))), X the
identity or the inverse and beta = phi1 or phi2. beta and its derivative are unknown, but both
enter linearly: per cell, the force error is -V0 F beta (X(B) - X(C)) D_a and the stiffness
error holds beta (the derivative of F (X(B) - X(C))) plus F (X(B) - X(C)) (x) dbeta/dF, dbeta/dF
a combination of the gradients of I1, I2 and J (beta depends on the invariants alone). The fit:
four unknowns per cell (beta and the three coefficients of dbeta) against the force and
stiffness errors, by least squares; named when it leaves both within the tolerance.
"""

from __future__ import annotations

from dataclasses import replace
from typing import List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances

__all__ = ["fit_b_for_c", "b_for_c_findings", "b_for_c_reading"]

_WORDS = {
    "C": "B = F F^T used for C = F^T F in the C term of the stress (S = phi0 I + phi1 C + "
    "phi2 C^-1)",
    "C^-1": "B^-1 used for C^-1 in the C^-1 term of the stress (S = phi0 I + phi1 C + phi2 C^-1)",
}


def _cell_bases(points, cells, x, which: str):
    """Per cell: force column of beta (m, 12) and stiffness bases (m, 4, 12, 12) of beta and of
    the coefficients of dbeta/dF on dI1/dF, dI2/dF, dJ/dF, with V0 and D.
    """
    V0, D, F = cell_kinematics(points, cells, x)
    Ft = F.swapaxes(1, 2)
    B, C = F @ Ft, Ft @ F
    eye = np.eye(3)
    if which == "C":
        Bi, Ci = None, None
        diff = B - C
    else:
        Bi, Ci = np.linalg.inv(B), np.linalg.inv(C)
        diff = Bi - Ci
    FX = F @ diff  # P' - P = beta F (X(B) - X(C))
    m = F.shape[0]
    # dP/dF_lj of beta F (X(B) - X(C)) at fixed beta: M[k, i, l, j]
    M = np.einsum("kl,mij->mkilj", eye, diff)
    for ll in range(3):
        for j in range(3):
            H = np.zeros((3, 3))
            H[ll, j] = 1.0
            dB = H @ Ft + F @ H.T
            dC = H.T @ F + Ft @ H
            if which == "C":
                dX = dB - dC
            else:
                dX = -(Bi @ dB @ Bi) + (Ci @ dC @ Ci)
            M[:, :, :, ll, j] += F @ dX
    C_tr = np.trace(C, axis1=1, axis2=2)
    grads = [
        2.0 * F,
        2.0 * (C_tr[:, None, None] * F - F @ C),
        np.linalg.det(F)[:, None, None] * np.linalg.inv(F).swapaxes(1, 2),
    ]
    Ms = [M] + [np.einsum("mki,mlj->mkilj", FX, g) for g in grads]
    bases = np.stack(
        [
            (V0[:, None, None, None, None] * np.einsum("mai,mkilj,mbj->makbl", D, Mk, D)).reshape(
                m, 12, 12
            )
            for Mk in Ms
        ],
        axis=1,
    )
    force = (-V0[:, None, None] * np.einsum("mki,mai->mak", FX, D)).reshape(m, 12)
    return force, bases


def fit_b_for_c(
    points, cells, x, df: np.ndarray, dK: sp.spmatrix, s: Scales, which: str
) -> Tuple[float, float, np.ndarray]:
    """(force residual, stiffness residual, beta (m,)) of the fit, relative to the scales."""
    force, bases = _cell_bases(points, cells, x, which)
    m, N = cells.shape[0], 3 * points.shape[0]
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    keys = (np.repeat(dof, 12, axis=1).astype(np.int64) * N + np.tile(dof, (1, 12))).ravel()
    pattern, where = np.unique(keys, return_inverse=True)
    where = where.reshape(m, 144)
    rows, cols, vals = [dof.ravel()], [np.repeat(4 * np.arange(m), 12)], [force.ravel() / s.force]
    for k in range(4):
        rows.append(N + where.ravel())
        cols.append(np.repeat(4 * np.arange(m) + k, 144))
        vals.append(bases[:, k].reshape(-1) / s.stiffness)
    A = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(N + pattern.size, 4 * m),
    )
    Dc = sp.coo_matrix(dK)
    dkeys = Dc.row.astype(np.int64) * N + Dc.col
    pos = np.searchsorted(pattern, dkeys)
    inside = (pos < pattern.size) & (pattern[np.minimum(pos, pattern.size - 1)] == dkeys)
    b = np.zeros(N + pattern.size)
    b[:N] = np.asarray(df).ravel() / s.force
    np.add.at(b, N + pos[inside], Dc.data[inside] / s.stiffness)
    outside = float(np.linalg.norm(Dc.data[~inside])) / s.stiffness
    norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    norms[norms == 0] = 1.0
    As = (A @ sp.diags(1.0 / norms)).tocsr()
    # 4m unknowns: the normal equations, solved through their eigen-decomposition (directions
    # the data do not see are left out) and refined on the residual, reach the least-squares
    # solution to round-off where LSQR stalls above the tolerance.
    w, V = np.linalg.eigh((As.T @ As).toarray())
    keep = w > 1e-13 * w.max()
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    c = np.zeros(As.shape[1])
    for _ in range(4):
        c += V @ (inv * (V.T @ (As.T @ (b - As @ c))))
    c = c / norms
    r = A @ c - b
    return float(np.linalg.norm(r[:N])), float(np.hypot(np.linalg.norm(r[N:]), outside)), c[0::4]


def b_for_c_findings(points, cells, x, df, dK, s: Scales, tol: Tolerances) -> List[Finding]:
    """The B-for-C stress mistakes the errors fit (several: ambiguous)."""
    found = []
    for which, words in _WORDS.items():
        fr, kr, beta = fit_b_for_c(points, cells, x, df, dK, s, which)
        if fr <= tol.force and kr <= tol.stiffness:
            q = np.percentile(beta, [0, 50, 100])
            found.append(
                Finding(
                    "stress-b-for-c",
                    f"C and B confused in a hand-written stress: {words}",
                    FULL,
                    "the force and stiffness errors fitted per cell as P' - P = beta F (X(B) - "
                    "X(C)), beta a function of the invariants (4 unknowns per cell), leave force "
                    f"error {fr:.1e} and stiffness error {kr:.1e}; fitted beta (that term's "
                    f"coefficient) from {q[0]:.4g} to {q[2]:.4g} Pa, median {q[1]:.4g}",
                    {"term": which, "force_after": fr, "stiffness_after": kr},
                )
            )
    return ambiguous(found)


#: Largest mesh (cells) the fit is tried on: a dense eigen-decomposition of 4m unknowns.
MAX_CELLS = 800


def b_for_c_reading(diag, ci, out, ref, s: Scales) -> Optional[object]:
    """``diag`` (a failed case nothing explained yet) with a B-for-C stress named first;
    unchanged when neither fits.
    """
    if ci.cells.shape[0] > MAX_CELLS:
        return diag
    found = b_for_c_findings(
        ci.points,
        ci.cells,
        ci.positions,
        np.asarray(out.force) - np.asarray(ref.force),
        (sp.csr_matrix(out.stiffness) - sp.csr_matrix(ref.stiffness)).tocsr(),
        s,
        diag.tolerances,
    )
    if not found:
        return diag
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*found, *rest])
