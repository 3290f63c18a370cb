"""The material tangent's blocks in the principal frame of C, one of them wrong.

A spectral engine (Simo and Taylor's principal-stretch form, the usual way to Ogden-type
materials) builds the material tangent of an isotropic energy in the eigenbasis N_a of C,
where it has two kinds of entries only:

- the **principal block** CC_aabb (a 3 x 3 matrix from the second derivatives of W in the
  stretches and the principal stresses' own terms), its diagonal CC_aaaa and its off-diagonal
  CC_aabb (a != b);
- the term -S_a / lambda_a^2 of the diagonal (CC_aaaa = (1/lambda_a) d(W_a / lambda_a)
  /dlambda_a: the quotient rule's second term, the one a hand derivation drops), a part of its
  own, predicted from the oracle's principal stresses;
- the **pair terms** CC_abab = CC_abba (a != b), from the divided differences
  (S_a - S_b) / (lambda_a^2 - lambda_b^2) that turn the principal directions, with their own
  limit where two stretches coincide;

then rotates it back, CC_IJKL = N_Ia N_Jb N_Kc N_Ld CC_abcd. A slip in one of these (a pair
term written for one index order only, a factor on it, a term of the principal block left out)
scales one kind of entry. Here the oracle's per-cell CC (from its element split) is rotated into
each cell's eigenbasis of C, cut into these parts, each part rotated back and assembled as a
material stiffness V0 D_a F CC_part F D_b, and the stiffness error K - K_o fitted by one or two
of them (with the geometric stiffness, from the oracle's S, as a further part), as the Voigt
blocks are (:func:`conformance.diagnosis.tangent.fit_parts`): named when a fit leaves the
stiffness within the tolerance, the force right. Where F is diagonal (a uniaxial state) the
principal frame is the global one and these parts are the Voigt blocks the run's own tangent
parts already try; the random state's rotated frames tell them apart.
"""

from __future__ import annotations

from typing import Dict, List

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.coincident_stretches import repeated_pair, without_plane
from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola, split_reading
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.fractions import simple_fraction
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.second_derivative import curvature_of, fit_cell_term
from conformance.diagnosis.strain_differences import material_stiffness
from conformance.diagnosis.tangent import describe_coefficient, fit_parts
from conformance.diagnosis.voigt_maps import geometric_stiffness
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "principal_masks",
    "rotate_tangent",
    "principal_parts",
    "principal_block_findings",
    "principal_frame_isotropic",
    "principal_block_reading",
]


def principal_masks() -> Dict[str, np.ndarray]:
    """(3, 3, 3, 3) 0/1 masks of the entries of a tangent in the principal frame, by part."""
    a = np.arange(3)
    i, j, k, l = np.meshgrid(a, a, a, a, indexing="ij")
    diagonal = (i == j) & (k == l) & (i == k)
    off = (i == j) & (k == l) & (i != k)
    same = (i != j) & (i == k) & (j == l)
    crossed = (i != j) & (i == l) & (j == k)
    pair = same | crossed
    return {
        "principal block of the material tangent (CC_aabb in the eigenbasis of C)": (
            diagonal | off
        ).astype(float),
        "diagonal of the principal block (CC_aaaa in the eigenbasis of C)": diagonal.astype(float),
        "off-diagonal of the principal block (CC_aabb, a != b, in the eigenbasis of C)": off.astype(
            float
        ),
        "pair (shear) terms of the material tangent in the eigenbasis of C (CC_abab, a != b: "
        "the divided differences (S_a - S_b) / (lambda_a^2 - lambda_b^2))": pair.astype(float),
        # one index order of the pair terms alone: an engine that writes CC_abab and not its
        # minor-symmetric twin CC_abba (or the other way round)
        "pair (shear) terms between principal directions in the order CC_abab alone (a != b; "
        "their twins CC_abba are the other order: written for one index order only, the minor "
        "symmetry lost)": same.astype(float),
        "pair (shear) terms between principal directions in the order CC_abba alone (a != b; "
        "their twins CC_abab are the other order: written for one index order only, the minor "
        "symmetry lost)": crossed.astype(float),
    }


_QUOTIENT = (
    "the term -S_a / lambda_a^2 of the principal block's diagonal (the derivative of the 1 / "
    "lambda_a in S_a = (1/lambda_a) dW/dlambda_a: the quotient rule's second term)"
)


def rotate_tangent(CC: np.ndarray, N: np.ndarray, back: bool = False) -> np.ndarray:
    """CC (m, 3, 3, 3, 3) into the per-cell basis N (m, 3, 3; columns N_a), or back
    (N CC N^T on every index).
    """
    if back:
        return np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", N, N, N, N, CC, optimize=True)
    return np.einsum("mIa,mJb,mKc,mLd,mIJKL->mabcd", N, N, N, N, CC, optimize=True)


def _principal_frame(split: ElementSplit):
    """(S (m, 3, 3), eigenvalues w (m, 3) and eigenvectors N (m, 3, 3) of C, the oracle's CC in
    each cell's eigenbasis (m, 3, 3, 3, 3)) per cell of the oracle's split.
    """
    t = cell_tensors(*cell_piola(split), split.F)
    w, N = np.linalg.eigh(t.C)
    return t.S, w, N, rotate_tangent(t.CC, N)


def principal_parts(split: ElementSplit, frame=None) -> Dict[str, sp.csr_matrix]:
    """The assembled material stiffness of each part of :func:`principal_masks` (oracle's CC per
    cell rotated into each cell's eigenbasis of C, masked, rotated back), and the geometric
    stiffness; parts that are zero here dropped. frame: :func:`_principal_frame`'s, if known.
    """
    S, w, N, hat = frame if frame is not None else _principal_frame(split)
    out = {}
    for name, mask in principal_masks().items():
        out[name] = material_stiffness(split, rotate_tangent(hat * mask, N, back=True))
    # the quotient rule's second term of CC_aaaa = (1/lambda_a) d/dlambda_a (W_a / lambda_a):
    # -S_a / lambda_a^2, from the oracle's S with nothing else
    S_aa = np.einsum("mIa,mIJ,mJa->ma", N, S, N)
    quotient = np.zeros_like(hat)
    for a in range(3):
        quotient[:, a, a, a, a] = -S_aa[:, a] / w[:, a]
    out[_QUOTIENT] = material_stiffness(split, rotate_tangent(quotient, N, back=True))
    out["geometric stiffness"] = geometric_stiffness(split, S)
    scale = max(float(abs(m).max()) for m in out.values())
    return {k: v for k, v in out.items() if float(abs(v).max()) > 1e-12 * scale}


def _isotropic_in_frame(hat: np.ndarray) -> bool:
    """True when the oracle's CC in each cell's eigenbasis of C (``hat``) has only
    principal-block and pair entries (an isotropic energy): else the parts do not add up to
    the tangent.
    """
    kept = np.clip(sum(principal_masks().values()), 0.0, 1.0)
    return float(np.abs(hat * (1.0 - kept)).max()) <= 1e-8 * float(np.abs(hat).max())


def principal_frame_isotropic(split: ElementSplit) -> bool:
    """True when the oracle's per-cell material tangent, in each cell's eigenbasis of C, has
    only principal-block and pair entries (an isotropic law: its spectral form exists).
    """
    return _isotropic_in_frame(_principal_frame(split)[3])


def _simple(c: float) -> bool:
    """True for a coefficient that is a simple fraction (denominator at most 4, to 1e-6): a
    block left out, halved, doubled, its sign flipped, one index order of two.
    """
    return simple_fraction(c, 4, 1e-6) is not None


def _along_j_curvature(
    split: ElementSplit, D: sp.csr_matrix, K0: sp.csr_matrix, tol: float
) -> bool:
    """True on a state with one J where the stiffness error is also a per-cell multiple of
    V0 dJ (x) dJ (a volumetric U''(J), or any term along C^-1 (x) C^-1): in the eigenbasis of C
    that is a principal-block tensor too, and the blocks cannot be told from it there.
    """
    J = np.linalg.det(split.F)
    if np.ptp(J) > 1e-9 * float(np.mean(np.abs(J))):
        return False
    basis = curvature_of(split.V0, split.D, split.F, "J")
    residual, _ = fit_cell_term(split.cells, basis, D, K0)
    return residual <= tol


def principal_block_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The principal-frame parts whose fit (one or two parts) leaves the engine's stiffness
    within the tolerance, the force right; [] otherwise.
    """
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    e = errors(f, K, None, f0, K0, 0.0, s)
    if e.force > tol.force or e.stiffness <= tol.stiffness:
        return []  # the force wrong, or nothing to explain in the stiffness
    frame = _principal_frame(split)
    if not _isotropic_in_frame(frame[3]):
        return []
    parts = principal_parts(split, frame)
    K0 = sp.csr_matrix(K0)
    D = (sp.csr_matrix(K) - K0).tocsr()
    ok, _ = fit_parts(D, K0, parts, tol.stiffness)
    plane = ""
    pair = repeated_pair(split) if ok is None else None
    if pair is not None:
        # Two equal stretches: in their plane the pair terms' blocks depend on the basis each
        # eigen-solver picks (the engine's and this one differ in the last bits of C), so the
        # in-plane tangent is left free and the parts are fitted on what is outside it.
        project = without_plane(split, pair)
        projected = {k: project(v) for k, v in parts.items()}
        ok, _ = fit_parts(project(D), K0, projected, tol.stiffness, max_parts=1)
        if ok is not None and not _simple(ok.coefficients[0]):
            # with the plane free, a free coefficient fits more than one block's slip (a
            # volumetric U'' along C^-1 (x) C^-1 too): only a slip in simple numbers is said
            ok = None
        plane = (
            "; on this homogeneous state two principal stretches are equal, and the tangent in "
            "their plane (whose basis each eigen-solver picks its own way, so that a part's "
            "share there cannot be predicted) was left free, six numbers per cell: the parts "
            "are fitted on the rest"
        )
    if ok is None or all(n == "geometric stiffness" for n in ok.names):
        return []  # the geometric part alone is the run's own tangent parts' to say
    if len(ok.names) > 1 and not all(_simple(c) for c in ok.coefficients):
        # two blocks with a free coefficient each fit more than two blocks' slips (seen: the
        # sign of MJED's antisymmetric d2J block, on a uniaxial state, fitted as the principal
        # block's off-diagonal x 0.697 and the pair terms CC_abba x -1)
        return []
    if _along_j_curvature(split, D, K0, tol.stiffness):
        return []
    words = " and ".join(describe_coefficient(n, c) for n, c in zip(ok.names, ok.coefficients))
    return [
        Finding(
            "principal-block",
            f"a spectral tangent with one block wrong: {words}"
            + (" (in the plane of the two equal stretches: fitted freely)" if plane else ""),
            FULL,
            "the oracle's per-cell material tangent rotated into each cell's eigenbasis of C, "
            "cut into its principal block and its pair terms, each rotated back and assembled: "
            "K - K_oracle = "
            + " + ".join(f"{c:+.6g} x [{n}]" for n, c in zip(ok.names, ok.coefficients))
            + f" leaves a stiffness error of {ok.residual:.1e}; the force matches"
            + plane,
            {
                "parts": list(ok.names),
                "coefficients": list(ok.coefficients),
                "plane_free": bool(plane),
            },
        )
    ]


def principal_block_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing named) with a spectral tangent's wrong block named
    first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (principal_block_findings,))
