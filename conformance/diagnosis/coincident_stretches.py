"""The tangent where two principal stretches coincide: an error the same in every cell, in the
plane of the two equal stretches alone.

A spectral engine's tangent holds the divided differences (S_a - S_b) / (lambda_a^2 -
lambda_b^2) between principal directions; where two stretches are equal (a uniaxial or an
equibiaxial state, the rest state) it needs their limit, and that branch is a classic place for
a slip: the limit taken from one principal stress only, the equal eigenvalues perturbed apart
by a small number, or closed-form (trigonometric) eigenvalues that lose their digits near
coincidence. Such an error lives only at such states, so the probes around them (which part
the equal stretches) do not repeat it, and it would read as round-off noise; it is not noise.

Evidence, on a homogeneous state (every cell with the same C, to 1e-10) with exactly two equal
eigenvalues of C: the stiffness error is fitted by a tangent change of each cell in the plane of
its two equal stretches alone (six numbers per cell, the 2-D elasticity tensor's entries in the
plane of that cell's own eigenvectors, which round-off turns from cell to cell), assembled as
V0 D_a F dCC F D_b, by sparse least squares. Round-off drawn per entry leaves most of itself
(a cell's 78 entries against six numbers), a formula error outside that plane leaves its part
outside; named when the fit accounts for :data:`SYSTEMATIC` of the error, the force right:
fully when it leaves the stiffness within the tolerance, partly otherwise.
"""

from __future__ import annotations

from typing import List, Optional

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import factorized, lsqr

from conformance.diagnosis.elements import ElementSplit, assemble, split_reading
from conformance.diagnosis.findings import FULL, PARTIAL, Finding
from conformance.diagnosis.strain_differences import material_stiffness
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "SYSTEMATIC",
    "plane_columns",
    "without_plane",
    "repeated_pair",
    "in_plane_fit",
    "coincident_findings",
    "coincident_reading",
]

#: Share of the stiffness error the in-plane changes must account for (round-off cannot).
SYSTEMATIC = 0.999
#: Relative spread of C over the cells, and gap of two eigenvalues, read as equal.
SAME = 1e-10


def _repeated_pair(C: np.ndarray) -> Optional[np.ndarray]:
    """The indices (2,) of the two equal eigenvalues of C (3, 3), ascending as eigh orders
    them; None unless exactly two are equal.
    """
    w = np.linalg.eigvalsh(C)
    close = np.abs(np.diff(w)) <= SAME * np.abs(w).max()
    if close.sum() != 1:
        return None
    k = int(np.flatnonzero(close)[0])
    return np.array([k, k + 1])


def _plane_tensors(E: np.ndarray) -> np.ndarray:
    """(6, m, 3, 3, 3, 3) the six in-plane tangents with minor and major symmetry (the 2-D
    elasticity tensor's entries 1111, 2222, 1122, 1212, 1112, 2212) in the plane spanned by the
    columns of E (m, 3, 2), in global components.
    """
    t2 = np.zeros((6, 2, 2, 2, 2))
    for k, (a, b, c, d) in enumerate(
        ((0, 0, 0, 0), (1, 1, 1, 1), (0, 0, 1, 1), (0, 1, 0, 1), (0, 0, 0, 1), (1, 1, 0, 1))
    ):
        for p, q in {(a, b), (b, a)}:
            for r, s in {(c, d), (d, c)}:
                t2[k, p, q, r, s] = t2[k, r, s, p, q] = 1.0
    return np.einsum("mIa,mJb,mKc,mLd,kabcd->kmIJKL", E, E, E, E, t2, optimize=True)


def plane_columns(split: ElementSplit, pair: np.ndarray) -> tuple:
    """(A (n3^2, 6 m) CSC, T (6, m, 3, 3, 3, 3)): the assembled stiffness, flattened, of each
    cell's six in-plane tangents in the plane of its two equal principal stretches (``pair``:
    their indices among eigh's ascending eigenvalues; the plane's basis each cell's own
    eigenvectors of C).
    """
    m, n3 = split.V0.size, 3 * split.n
    C = split.F.swapaxes(1, 2) @ split.F
    _, N = np.linalg.eigh(C)
    T = _plane_tensors(N[:, :, pair])  # (6, m, 3, 3, 3, 3)
    Ke = (
        np.einsum(
            "maI,mkJ,nmJIML,mlM,mbL->nmakbl", split.D, split.F, T, split.F, split.D, optimize=True
        )
        * split.V0[None, :, None, None, None, None]
    )
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = (dof[:, :, None] * n3 + dof[:, None, :]).reshape(m, 144)
    cols = np.arange(6 * m).reshape(6, m)
    A = sp.coo_matrix(
        (
            Ke.reshape(6, m, 144).ravel(),
            (np.tile(rows, (6, 1)).ravel(), np.repeat(cols.ravel(), 144)),
        ),
        shape=(n3 * n3, 6 * m),
    ).tocsc()
    return A, T


def _flat(D: sp.spmatrix) -> np.ndarray:
    """(n3^2,) the entries of D (n3, n3), row-major."""
    n3 = D.shape[0]
    Dc = sp.coo_matrix(D)
    b = np.zeros(n3 * n3)
    np.add.at(b, Dc.row.astype(np.int64) * n3 + Dc.col, Dc.data)
    return b


def _solve(A: sp.csc_matrix, b: np.ndarray, m: int) -> np.ndarray:
    """The least-squares in-plane unknowns (6 m,) for the flattened error b."""
    return lsqr(A, b, atol=1e-14, btol=1e-14, iter_lim=20 * 6 * m)[0]


def without_plane(split: ElementSplit, pair: np.ndarray):
    """A function D (3n, 3n) -> D minus its least-squares fit by the in-plane tangents of
    :func:`plane_columns` (csr): what is left outside the plane of the two equal stretches,
    where each eigen-solver picks its own basis.
    """
    A, _ = plane_columns(split, pair)
    n3 = 3 * split.n
    used = np.unique(A.indices)
    A = A[used]
    # the normal equations factorised once (each part is projected): a small ridge for the
    # combinations of in-plane tangents that no entry sees
    G = (A.T @ A).tocsc()
    ridge = 1e-12 * float(G.diagonal().max())
    solve = factorized((G + ridge * sp.identity(G.shape[0], format="csc")).tocsc())

    def project(D: sp.spmatrix) -> sp.csr_matrix:
        b = _flat(D)
        r = b[used]
        b[used] = r - A @ solve(A.T @ r)
        return sp.csr_matrix(b.reshape(n3, n3))

    return project


def in_plane_fit(split: ElementSplit, D: sp.csr_matrix, pair: np.ndarray) -> tuple:
    """(per-cell dCC (m, 3, 3, 3, 3), explained share): the tangent change of each cell in the
    plane of its two equal principal stretches (six unknowns per cell, the plane's basis each
    cell's own eigenvectors of C) that best fits the stiffness error D (3n, 3n), by sparse least
    squares.
    """
    m = split.V0.size
    A, T = plane_columns(split, pair)
    b = _flat(D)
    used = np.unique(A.indices)
    if np.any(b[np.setdiff1d(np.flatnonzero(b), used)] != 0.0):
        return None, 0.0  # the error reaches entries no cell's tangent touches
    x = _solve(A[used], b[used], m)
    left = float(np.linalg.norm(A[used] @ x - b[used]))
    nb = float(np.linalg.norm(b))
    dCC = np.einsum("km,kmIJKL->mIJKL", x.reshape(6, m), T, optimize=True)
    return dCC, (1.0 - left / nb) if nb > 0 else 0.0


def repeated_pair(split: ElementSplit) -> Optional[np.ndarray]:
    """The indices (2,) of the two equal eigenvalues of C on a homogeneous state with exactly
    two equal; None otherwise.
    """
    C = split.F.swapaxes(1, 2) @ split.F
    if float(np.abs(C - C[:1]).max()) > SAME * float(np.abs(C).max()):
        return None  # not a homogeneous state
    return _repeated_pair(C[0])


def coincident_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The coincident-stretch tangent error, or []."""
    pair = repeated_pair(split)
    if pair is None:
        return []
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    base = errors(f, K, None, f0, K0, 0.0, s)
    if base.force > tol.force or base.stiffness <= tol.stiffness:
        return []
    D = (sp.csr_matrix(K) - K0).tocsr()
    dCC, explained = in_plane_fit(split, D, pair)
    if dCC is None or explained < SYSTEMATIC:
        return []
    shared = errors(f, K, None, f0, K0 + material_stiffness(split, dCC), 0.0, s)
    strength = FULL if shared.stiffness <= tol.stiffness else PARTIAL
    return [
        Finding(
            "coincident-stretches",
            "the tangent where two principal stretches coincide (a repeated eigenvalue of C "
            "here) wrong: the error lies in the plane of the two equal stretches alone, e.g. the "
            "limit of the divided difference (S_a - S_b) / (lambda_a^2 - lambda_b^2) taken "
            "wrongly, the equal eigenvalues perturbed apart, or eigenvalues that lose their "
            "digits near coincidence (a closed-form, trigonometric solution)",
            strength,
            "on this homogeneous state a tangent change of each cell in the plane of its two "
            f"equal principal stretches alone (six numbers per cell) accounts for "
            f"{100 * explained:.3f} % of the stiffness error (round-off would leave most of it: "
            f"a cell's 78 entries against six numbers); stiffness error left "
            f"{shared.stiffness:.1e} (against "
            f"{base.stiffness:.1e}); the force right. A state with distinct stretches (the "
            "probes, a random state) does not take that branch",
            {"explained": explained},
        )
    ]


def coincident_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing named) with the coincident-stretch tangent error named
    first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (coincident_findings,))
