"""A spectral engine's principal frame wrong: the eigenvectors of b for those of C, or the
eigenvalues paired with the wrong eigenvectors.

A spectral engine evaluates an isotropic energy in the principal stretches (the eigenvalues of
C) and assembles its stress and tangent on the eigenvectors N_a of C:
S = sum_a S_a N_a (x) N_a, CC likewise in the N_a basis. Two frame slips keep the energy right
(it reads the eigenvalues alone) and move the stress:

- **the eigenvectors of b = F F^T** (the spatial principal directions n_a = R N_a, F = R U)
  used where those of C belong: S' = R S R^T, CC' rotated likewise;
- **the eigenvalues paired with the wrong eigenvectors**: sorted (say descending) after the
  decomposition with the eigenvectors left in the solver's order, S' = sum_a S_sigma(a) N_a (x)
  N_a for a permutation sigma, CC' with its principal-frame indices permuted alike.

Each is predicted per cell from the oracle's S and CC (its element split) in the cell's
eigenbasis of C (ascending eigenvalues, as numpy.linalg.eigh gives them), assembled as a
total-Lagrangian engine does (P = F S', A = delta S' + F CC' F), in the force and the stiffness
or in the force alone (the tangent built right), nothing fitted; named when it matches the
engine within the tolerance and is not the oracle's own (where two stretches are equal a
permutation of them changes nothing and explains nothing), several as ambiguous. Only for an
energy whose stress is coaxial with C (isotropic): else there is no principal frame to slip.
"""

from __future__ import annotations

import itertools
from typing import List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    piola_element_forces,
    prediction_errors,
    split_reading,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.principal_blocks import rotate_tangent
from conformance.judge.compare import Scales, Tolerances

__all__ = ["frame_slips", "spectral_frame_findings", "spectral_frame_reading"]

_NAMES = ("smallest", "middle", "largest")


def frame_slips(
    S: np.ndarray, CC: np.ndarray, F: np.ndarray
) -> List[Tuple[str, str, np.ndarray, np.ndarray]]:
    """(code, words, S', CC') per slip: S (m, 3, 3), CC (m, 3, 3, 3, 3), F (m, 3, 3)."""
    C = F.swapaxes(1, 2) @ F
    _, N = np.linalg.eigh(C)  # ascending eigenvalues, columns N_a
    W, _, Vt = np.linalg.svd(F)
    R = W @ Vt  # F = R U
    out = [
        (
            "spectral-frame-b",
            "the principal directions taken from b = F F^T (the spatial ones, n_a = R N_a) where "
            "those of C belong: the stress and tangent assembled on the eigenvectors of b",
            R @ S @ R.swapaxes(1, 2),
            rotate_tangent(CC, R, back=True),
        )
    ]
    Nt = N.swapaxes(1, 2)
    S_hat = Nt @ S @ N
    CC_hat = rotate_tangent(CC, N)
    for perm in itertools.permutations(range(3)):
        if perm == (0, 1, 2):
            continue
        p = list(perm)
        Sp = S_hat[:, p][:, :, p]
        CCp = CC_hat[:, p][:, :, p][:, :, :, p][:, :, :, :, p]
        said = ", ".join(
            f"the {_NAMES[a]} eigenvector with the {_NAMES[b]} eigenvalue's stress"
            for a, b in enumerate(perm)
            if a != b
        )
        out.append(
            (
                "spectral-pairing-" + "".join(map(str, perm)),
                "the principal stretches paired with the wrong eigenvectors (eigenvalues "
                f"reordered after the decomposition, the eigenvectors not): {said}",
                N @ Sp @ Nt,
                rotate_tangent(CCp, N, back=True),
            )
        )
    return out


def _coaxial(S: np.ndarray, C: np.ndarray) -> bool:
    """True when S commutes with C in every cell (an isotropic energy's stress), to round-off."""
    scale = float(np.abs(S).max() * np.abs(C).max())
    return float(np.abs(S @ C - C @ S).max()) <= 1e-8 * scale


def spectral_frame_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The frame slips of :func:`frame_slips` whose assembly matches the engine (several:
    ambiguous); [] for a stress not coaxial with C.
    """
    t = cell_tensors(*cell_piola(split), split.F)
    if not _coaxial(t.S, t.C):
        return []
    F = split.F
    geo_right = np.einsum("ik,mJL->miJkL", np.eye(3), t.S)
    A_right = geo_right + np.einsum("miI,mIJKL,mkK->miJkL", F, t.CC, F, optimize=True)
    Ke_right = tangent_element_matrices(split.V0, split.D, A_right)
    found = []
    for code, words, S2, CC2 in frame_slips(t.S, t.CC, F):
        fe = piola_element_forces(split.V0, split.D, F @ S2)
        A = np.einsum("ik,mJL->miJkL", np.eye(3), S2) + np.einsum(
            "miI,mIJKL,mkK->miJkL", F, CC2, F, optimize=True
        )
        for where, Ke in (
            ("in the force and the stiffness", tangent_element_matrices(split.V0, split.D, A)),
            ("in the force alone (the tangent built right)", Ke_right),
        ):
            fv, Kv = assemble(split.cells, split.n, fe, Ke)
            e = prediction_errors(split, f, K, (fv, Kv), s, tol)
            if e is not None:
                found.append(
                    Finding(
                        code,
                        f"{words}, {where}",
                        FULL,
                        "the oracle's per-cell S and CC (from its element split) so moved in "
                        "each cell's eigenbasis of C and assembled on P = F S', A = delta S' + "
                        f"F CC' F (nothing fitted): force error {e.force:.1e}, stiffness error "
                        f"{e.stiffness:.1e}",
                        {"slip": code, "residual": max(e.force, e.stiffness)},
                    )
                )
                break
    return ambiguous(found, "their predictions differ by less than the tolerance here")


def spectral_frame_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (nothing named) with a spectral engine's frame slip named first
    (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (spectral_frame_findings,))
