"""Differences of P with a step relative to each entry of F: the zero entries' columns are noise.

An engine that takes dP/dF by differences, column (k, L) from P(F +- h_kL E_kL), with a step
relative to the entry, h_kL = eps max(|F_kL|, tiny), gets for an entry of F that is zero (every
off-diagonal entry of a stretch without rotation) a step of round-off size: that column of
dP/dF is the round-off of P over h, noise orders of magnitude above the tangent, while the
others are right to the differences' own round-off. The stiffness error then has a signature
read off the engine's K without fitting anything:

- along the affine displacement d = E_kL X of each entry that is not zero (every cell's F moved
  by E_kL alone, K d = sum_c V_c G_c^T A'_c[:, :, k, L]) it is within the differences'
  round-off, sqrt(u) of the oracle's K d;
- along some zero entry's it is beyond that;
- it is noise: not symmetric (:data:`conformance.diagnosis.piola_slips.ASYMMETRY`), and not one
  error repeated in every cell: along a zero entry's affine displacement it reaches the
  interior nodes (:data:`INTERIOR`), where an error of the same (P, A) in every cell (a formula
  wrong at the state's one F) cancels, as a constant stress has no divergence.

Read only where the force is right and every cell's F has the same zero entries (relative to
its largest, :data:`ZERO`), some but not all of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import ElementSplit, assemble, split_reading
from conformance.diagnosis.findings import PARTIAL, Finding
from conformance.diagnosis.piola_slips import ASYMMETRY, NUMERICAL
from conformance.judge.compare import Scales, Tolerances

__all__ = [
    "ZERO",
    "INTERIOR",
    "EntrySteps",
    "entry_steps",
    "entry_step_findings",
    "entry_step_reading",
]

#: An entry of F is zero below this times the largest entry of its cell.
ZERO = 1e-12

#: Least share of the error along a zero entry's affine displacement on interior nodes.
INTERIOR = 0.1


@dataclass(frozen=True)
class EntrySteps:
    """zero: (3, 3) the entries of F that are zero in every cell; along: (3, 3) the relative
    stiffness error ||(K - K_o) d|| / ||K_o d|| along each entry's affine displacement;
    interior: (3, 3) the share of that error on interior nodes; asymmetry: of K - K_o.
    """

    zero: np.ndarray
    along: np.ndarray
    interior: np.ndarray
    asymmetry: float

    @property
    def holds(self) -> bool:
        nz, z = ~self.zero, self.zero
        noisy = z & (self.along > NUMERICAL)
        return bool(
            np.all(self.along[nz] <= NUMERICAL)
            and np.any(noisy)
            and np.any(self.interior[noisy] >= INTERIOR)
            and self.asymmetry >= ASYMMETRY
        )


def entry_steps(
    split: ElementSplit, points: np.ndarray, K: sp.spmatrix, K_o: sp.spmatrix
) -> Optional[EntrySteps]:
    """The signature of :class:`EntrySteps` (None: the cells' F do not share their zero entries,
    or have none, or all).
    """
    F = split.F
    zero = np.abs(F) <= ZERO * np.abs(F).max(axis=(1, 2))[:, None, None]
    common = zero[0]
    if not np.all(zero == common) or not common.any() or common.all():
        return None
    n = points.shape[0]
    D = (sp.csr_matrix(K) - sp.csr_matrix(K_o)).tocsr()
    Ko = sp.csr_matrix(K_o)
    # interior nodes: the cells' V G_a sum to zero there (no boundary face)
    VG = np.zeros((n, 3))
    np.add.at(VG, split.cells.ravel(), (split.V0[:, None, None] * split.D).reshape(-1, 3))
    inside = np.linalg.norm(VG, axis=1) <= 1e-12 * np.abs(VG).max()
    along = np.zeros((3, 3))
    interior = np.zeros((3, 3))
    for k in range(3):
        for L in range(3):
            d = np.zeros((n, 3))
            d[:, k] = points[:, L]  # dF = E_kL in every cell
            e = (D @ d.ravel()).reshape(n, 3)
            ne = float(np.linalg.norm(e))
            along[k, L] = ne / max(float(np.linalg.norm(Ko @ d.ravel())), 1e-300)
            interior[k, L] = float(np.linalg.norm(e[inside])) / ne if ne > 0 else 0.0
    nD = float(sparse_norm(D))
    asym = float(sparse_norm(D - D.T)) / (2.0 * nD) if nD > 0 else 0.0
    return EntrySteps(common, along, interior, asym)


def entry_step_findings(points: np.ndarray):
    """A finder (split, f, K, s, tol) -> findings for
    :func:`conformance.diagnosis.elements.split_reading`: the relative step named (partly
    explaining, as differences are) when the force is right and :class:`EntrySteps` holds.
    """

    def finder(split: ElementSplit, f, K, s: Scales, tol: Tolerances) -> List[Finding]:
        f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
        if np.linalg.norm(np.asarray(f) - f0) > tol.force * s.force:
            return []
        with np.errstate(all="ignore"):
            r = entry_steps(split, points, K, K0)
        if r is None or not r.holds:
            return []
        names = ", ".join(f"F_{k + 1}{L + 1}" for k, L in zip(*np.nonzero(r.zero)))
        nz = ~r.zero
        noisy = r.zero & (r.along > NUMERICAL)
        return [
            Finding(
                "finite-difference-entry-steps",
                "a finite-difference dP/dF with a step relative to each entry of F (h = eps "
                "|F_kl|, floored at round-off size): the entries of F that are zero on this "
                f"state ({names}) get a step of round-off size, and the round-off of P over "
                "that step swamps their columns of the tangent; use an absolute step (about "
                "1e-6 for F) or one relative to the size of F",
                PARTIAL,
                "the force matches; along the displacements that move every cell's F by one "
                "entry, the stiffness error is at most "
                f"{r.along[nz].max():.1e} of the oracle's for the entries that are not zero "
                "(the round-off of differences) and up to "
                f"{r.along[noisy].max():.1e} for the zero ones; it is noise: not symmetric "
                f"(antisymmetric share {r.asymmetry:.2f}) and reaching the interior nodes "
                f"({r.interior[noisy].max():.2f} of the error there), where one error repeated "
                "in every cell would cancel",
                {
                    "zero_entries": [[int(k), int(L)] for k, L in zip(*np.nonzero(r.zero))],
                    "along": r.along.tolist(),
                    "interior": r.interior.tolist(),
                    "asymmetry": r.asymmetry,
                },
            )
        ]

    return finder


def entry_step_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing explaining the stiffness) with a relative step named
    first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (entry_step_findings(ci.points),))
