"""A total-Lagrangian assembly on the first Piola stress with one mistake in P or A.

A total-Lagrangian engine (FElupe, textbook and Holzapfel-style codes) computes per cell the
second Piola stress S and the material tangent CC = dS/dE, and assembles with the first Piola
stress and the first elasticity tensor

    P = F S,    A_iJkL = delta_ik S_JL + F_iI CC_IJKL F_kK,
    f_a = -V P G_a,    K_ab,ik = V G_aJ A_iJkL G_bL,

G_a = dN_a/dX the reference shape gradients, V the rest volume (the sign convention of
docs/conventions.md: f = -dW/dx). Its mistakes are tested here on the oracle's own per-cell S
and CC (:func:`conformance.diagnosis.invariant_pieces.cell_tensors` of the element split), each
reassembled with one mistake (NumPy, nothing fitted):

- **the Piola stress**: P computed as S F, F^T S or S F^T for F S, in the force alone (the
  stiffness built right), in the force and the geometric part of A (the derivative of the
  wrong product at fixed S), or with the whole tangent the exact derivative of the wrong
  product (S F^T so differentiated is P^T, a stress measure of
  :mod:`conformance.diagnosis.elements`, not repeated here);
- **the material part** F_iI CC_IJKL F_kK contracted with F^T on one or both sides
  (F_Ii for F_iI), or with CC's indices paired wrongly (CC_IKJL for CC_IJKL);
- **the geometric part** delta_ik S_JL missing, doubled, built with P (delta_ik P_JL, or P
  transposed), or with its index pairs swapped (S_ik delta_JL);
- **the element contraction** G_aL A_iJkL G_bJ, the two gradients swapped (the same
  stiffness as CC_ILKJ for CC_IJKL in the material part: one variant says both);
- **the strain-displacement matrix** of a Voigt engine (Bathe's B = B_L0 + B_L1, the variation
  dE = sym(F^T grad du), so that r = V0 B^T S and K = V0 B^T D B + K_geo) built from another
  matrix G than F (:data:`B_MATRICES`: B_L0 alone, B_L1 from the displacement gradient
  transposed, negated, halved or doubled): P = G S and the material part G CC G, in the force
  and the stiffness, in the material stiffness alone (the force's B right: Bathe's K_L0 used
  for K_L0 + K_L1), or in the force alone; the geometric part, built from S alone, right.

(The element matrix's (a, i, b, k) entries laid out in another order before the node-major
scatter, e.g. an einsum's 'mabik' reshaped as if 'maibk', is storage: the local-order family of
:func:`conformance.diagnosis.elements.order_findings`.) A variant is named only when its force
and stiffness match the engine's within the case's tolerance and its prediction is not the
oracle's own (where F and S are diagonal, a uniaxial state, S F = F S and several variants
predict the oracle: they explain nothing there); several that match are said as ambiguous. The
correct variant must reproduce the split (a soundness check of the per-cell S and CC: otherwise
nothing is claimed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    prediction_errors,
    split_reading,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "PRODUCTS",
    "B_MATRICES",
    "B_WHERE",
    "PiolaVariant",
    "PIOLA_VARIANTS",
    "piola_variant_output",
    "piola_findings",
    "piola_force_findings",
    "piola_assembly_reading",
]

_EYE = np.eye(3)


def _t(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


#: code -> (the product in words, M(S, F): the engine's P) for the right F S and its confusions.
PRODUCTS = {
    "FS": ("F S", lambda S, F: F @ S),
    "SF": ("S F", lambda S, F: S @ F),
    "FtS": ("F^T S", lambda S, F: _t(F) @ S),
    "SFt": ("S F^T = P^T", lambda S, F: S @ _t(F)),
}


#: The same wrong product as a Voigt engine writes it (r = V0 B^T S).
_VOIGT_GLOSS = {
    "FtS": " (in a Voigt engine: the strain-displacement matrix's B_L1 built from the "
    "displacement gradient transposed, H^T for H)",
}


def _geometric(S: np.ndarray, P: np.ndarray) -> np.ndarray:
    """delta_ik S_JL (m, 3, 3, 3, 3), the right geometric part."""
    return np.einsum("ik,mJL->miJkL", _EYE, S)


def _material(F: np.ndarray, CC: np.ndarray, left: str = "miI", right: str = "mkK") -> np.ndarray:
    """F CC F (m, 3, 3, 3, 3) as A[i, J, k, L], F's indices as ``left`` and ``right`` say."""
    return np.einsum(f"{left},mIJKL,{right}->miJkL", F, CC, F, optimize=True)


#: Geometric parts: code -> (words, (S, P) -> (m, 3, 3, 3, 3)).
GEOMETRIC = {
    "missing": (
        "the geometric (initial-stress) part delta_ik S_JL of the first elasticity tensor A "
        "missing (A = F_iI CC_IJKL F_kK alone)",
        lambda S, P: np.zeros(S.shape[:1] + (3, 3, 3, 3)),
    ),
    "doubled": (
        "the geometric (initial-stress) part delta_ik S_JL of the first elasticity tensor A "
        "added twice",
        lambda S, P: 2.0 * _geometric(S, P),
    ),
    "piola": (
        "the geometric (initial-stress) part of the first elasticity tensor A built with the "
        "first Piola stress P = F S instead of S: delta_ik P_JL for delta_ik S_JL",
        lambda S, P: np.einsum("ik,mJL->miJkL", _EYE, P),
    ),
    "piola-transposed": (
        "the geometric (initial-stress) part of the first elasticity tensor A built with P^T "
        "(P = F S) instead of S: delta_ik P_LJ for delta_ik S_JL",
        lambda S, P: np.einsum("ik,mLJ->miJkL", _EYE, P),
    ),
    "swapped": (
        "the geometric (initial-stress) part of the first elasticity tensor A with its index "
        "pairs swapped: S_ik delta_JL (S on the spatial indices) for delta_ik S_JL",
        lambda S, P: np.einsum("mik,JL->miJkL", S, _EYE),
    ),
}

#: Material parts: code -> (words, (F, CC) -> (m, 3, 3, 3, 3)).
MATERIAL = {
    "F-transposed": (
        "the material part of the first elasticity tensor A contracted with F^T on both sides: "
        "F_Ii CC_IJKL F_Kk for F_iI CC_IJKL F_kK (the einsum indices of F swapped; in a Voigt "
        "engine, the strain-displacement matrix of B^T D B with B_L1 built from H^T)",
        lambda F, CC: _material(F, CC, "mIi", "mKk"),
    ),
    "F-transposed-left": (
        "the material part of the first elasticity tensor A contracted with F^T on its first "
        "side: F_Ii CC_IJKL F_kK for F_iI CC_IJKL F_kK",
        lambda F, CC: _material(F, CC, "mIi", "mkK"),
    ),
    "F-transposed-right": (
        "the material part of the first elasticity tensor A contracted with F^T on its second "
        "side: F_iI CC_IJKL F_Kk for F_iI CC_IJKL F_kK",
        lambda F, CC: _material(F, CC, "miI", "mKk"),
    ),
    "CC-pairs": (
        "the material part of the first elasticity tensor A with CC's index pairs taken wrongly: "
        "F_iI CC_IKJL F_kK for F_iI CC_IJKL F_kK",
        lambda F, CC: np.einsum("miI,mIKJL,mkK->miJkL", F, CC, F, optimize=True),
    ),
}


#: The matrix G an engine's strain-displacement matrix is built from (dE = sym(G^T grad du), so
#: that its force carries P = G S and its material stiffness G CC G), code -> (words, G(F));
#: the right one is F = I + H (H the displacement gradient).
B_MATRICES = {
    "linear": (
        "B_L0 alone, the linear (small-strain) part: B_L1, the initial-displacement part from "
        "the displacement gradient H, dropped (G = I, so P = S)",
        lambda F: np.broadcast_to(_EYE, F.shape),
    ),
    "transposed": (
        "B_L1 built from the displacement gradient transposed (H^T for H, so G = F^T)",
        lambda F: _t(F),
    ),
    "reversed": (
        "B_L1 built from the displacement gradient with its sign reversed (-H for H, so "
        "G = 2 I - F)",
        lambda F: 2.0 * _EYE - F,
    ),
    "half": (
        "B_L1 halved (H/2 for H, so G = I + H/2: the 1/2 of E's quadratic term H^T H / 2 kept "
        "in its variation)",
        lambda F: 0.5 * (_EYE + F),
    ),
    "double": (
        "B_L1 doubled (2 H for H, so G = I + 2 H)",
        lambda F: 2.0 * F - _EYE,
    ),
}

#: Where an engine's wrong strain-displacement matrix enters, code -> words.
B_WHERE = {
    "both": "in the force r = V0 B^T S and in the material stiffness B^T D B",
    "stiffness": "in the material stiffness B^T D B alone (the force's B right: K_L0 without "
    "the initial-displacement part K_L1, or a B of its own)",
    "force": "in the force r = V0 B^T S alone (the stiffness's B right)",
}


@dataclass(frozen=True)
class PiolaVariant:
    """code; words: the mistake as an engineer would fix it; product: the engine's P
    (:data:`PRODUCTS`) in the force; tangent: "right" (A built right from S and CC),
    "geometric" (the geometric part the derivative of the product at fixed S) or "exact" (A
    the product's whole derivative); geometric, material: a part of A from :data:`GEOMETRIC`,
    :data:`MATERIAL` ("" : right); swap_gradients: K_ab = G_aL A_iJkL G_bJ; b_matrix: the
    strain-displacement matrix built from :data:`B_MATRICES`' G ("": from F), where
    :data:`B_WHERE` says.
    """

    code: str
    words: str
    product: str = "FS"
    tangent: str = "right"
    geometric: str = ""
    material: str = ""
    swap_gradients: bool = False
    b_matrix: str = ""
    b_where: str = "both"


#: The geometric part an engine gets from its wrong product: its derivative by F at fixed S.
_PRODUCT_GEOMETRIC = {"SF": "S_ik delta_JL", "FtS": "delta_iL S_kJ", "SFt": "S_iL delta_Jk"}


def _product_variants() -> List[PiolaVariant]:
    out = []
    for p in ("SF", "FtS", "SFt"):
        name = PRODUCTS[p][0]
        base = f"the first Piola stress computed as {name} instead of F S{_VOIGT_GLOSS.get(p, '')}"
        out.append(
            PiolaVariant(
                f"piola-{p}",
                f"{base} in the force (the stiffness built right from S and CC)",
                product=p,
            )
        )
        out.append(
            PiolaVariant(
                f"piola-{p}-geometric",
                f"{base}, in the force and in the geometric part of the first elasticity tensor "
                f"({_PRODUCT_GEOMETRIC[p]}, the derivative of {name} at fixed S, for "
                "delta_ik S_JL; the material part right)",
                product=p,
                tangent="geometric",
            )
        )
        if p != "SFt":  # S F^T differentiated exactly is P^T: elements' stress measures
            out.append(
                PiolaVariant(
                    f"piola-{p}-exact",
                    f"{base}, and the stiffness the exact derivative of {name} (force and "
                    "tangent both of the wrong product)",
                    product=p,
                    tangent="exact",
                )
            )
    return out


def _b_matrix_variants() -> List[PiolaVariant]:
    return [
        PiolaVariant(
            f"b-matrix-{code}" + ("" if where == "both" else f"-{where}"),
            f"the strain-displacement matrix B (Voigt: dE = sym(F^T grad du), B = B_L0 + B_L1) "
            f"with {words}, {B_WHERE[where]}; S, D and the geometric stiffness right",
            b_matrix=code,
            b_where=where,
        )
        for code, (words, _) in B_MATRICES.items()
        for where in B_WHERE
        # G = F^T in the force alone, or in the stiffness alone, is a variant above already
        # ("piola-FtS", "material-F-transposed")
        if code != "transposed" or where == "both"
    ]


#: The variants tested (the first is the correct assembly: a soundness check, never named).
PIOLA_VARIANTS: Tuple[PiolaVariant, ...] = (
    PiolaVariant("right", "the correct total-Lagrangian assembly"),
    *_product_variants(),
    *(PiolaVariant(f"geometric-{c}", w, geometric=c) for c, (w, _) in GEOMETRIC.items()),
    *(PiolaVariant(f"material-{c}", w, material=c) for c, (w, _) in MATERIAL.items()),
    PiolaVariant(
        "gradients-swapped",
        "the element stiffness contracted as G_aL A_iJkL G_bJ (the two shape gradients on each "
        "other's index) where K_ab,ik = G_aJ A_iJkL G_bL belongs; the same stiffness as the "
        "material part of A written F_iI CC_ILKJ F_kK for F_iI CC_IJKL F_kK (the geometric "
        "part, symmetric in J and L, is unchanged)",
        swap_gradients=True,
    ),
    *_b_matrix_variants(),
)


def _product_tangent(
    F: np.ndarray, S: np.ndarray, CC: np.ndarray, M: Callable, exact: bool
) -> np.ndarray:
    """dM(S, F)/dF (m, 3, 3, 3, 3) as A[i, J, k, L], by complex step (exact to round-off): with
    exact, S moves with F (dS = CC : sym(F^T dF)); else S is held (the geometric part).
    """
    h = 1e-30
    A = np.empty(F.shape[:1] + (3, 3, 3, 3))
    for k in range(3):
        for L in range(3):
            H = np.zeros((3, 3))
            H[k, L] = 1.0
            dS = 0.0
            if exact:
                FtH = _t(F) @ H
                dS = np.einsum("mIJKL,mKL->mIJ", CC, 0.5 * (FtH + _t(FtH)))
            A[:, :, :, k, L] = np.imag(M(S + 1j * h * dS, F + 1j * h * H)) / h
    return A


def piola_variant_output(
    split: ElementSplit, S: np.ndarray, CC: np.ndarray, v: PiolaVariant
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """Force (n, 3) and stiffness (3n, 3n) of an engine that assembles S and CC (per cell: (m, 3,
    3), (m, 3, 3, 3, 3)) as ``v``.
    """
    F, G, V = split.F, split.D, split.V0
    P = F @ S
    Pe = PRODUCTS[v.product][1](S, F)
    geo = _geometric(S, P)
    mat = _material(F, CC)
    if v.geometric:
        geo = GEOMETRIC[v.geometric][1](S, P)
    if v.material:
        mat = MATERIAL[v.material][1](F, CC)
    if v.b_matrix:
        Gm = B_MATRICES[v.b_matrix][1](F)
        if v.b_where in ("both", "force"):
            Pe = Gm @ S
        if v.b_where in ("both", "stiffness"):
            mat = _material(Gm, CC)
    A = geo + mat
    if v.tangent == "geometric":
        A = _product_tangent(F, S, CC, PRODUCTS[v.product][1], False) + mat
    elif v.tangent == "exact":
        A = _product_tangent(F, S, CC, PRODUCTS[v.product][1], True)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", Pe, G)
    contraction = "maL,miJkL,mbJ->maibk" if v.swap_gradients else "maJ,miJkL,mbL->maibk"
    Ke = V[:, None, None, None, None] * np.einsum(contraction, G, A, G, optimize=True)
    return assemble(split.cells, split.n, fe, Ke.reshape(-1, 12, 12))


def piola_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The variants of :data:`PIOLA_VARIANTS` whose assembly matches the engine and differs from
    the oracle's (several: ambiguous); none when the correct variant does not reproduce the
    split (then the per-cell S and CC are not trusted).
    """
    K = sp.csr_matrix(K)
    with np.errstate(all="ignore"):
        t = cell_tensors(*cell_piola(split), split.F)
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    found = []
    for v in PIOLA_VARIANTS:
        with np.errstate(all="ignore"):
            fv, Kv = piola_variant_output(split, t.S, t.CC, v)
        if not (np.all(np.isfinite(fv)) and np.all(np.isfinite(Kv.data))):
            continue
        if v.code == "right":
            if not tol.within(errors(f0, K0, None, fv, Kv, 0.0, s), energy=False):
                return []  # the reassembly does not reproduce the oracle: claim nothing
            continue
        e = prediction_errors(split, f, K, (fv, Kv), s, tol)
        if e is not None:
            found.append(
                Finding(
                    f"piola-assembly-{v.code}",
                    v.words,
                    FULL,
                    "the oracle's second Piola stress and material tangent per cell (from its "
                    f"element split, whose sum is the oracle's to {split.residual:.1e}) "
                    f"assembled on P and A so: force error {e.force:.1e}, stiffness error "
                    f"{e.stiffness:.1e}",
                    {"variant": v.code, "residual": max(e.force, e.stiffness)},
                )
            )
    return ambiguous(found, "their predictions differ by less than the tolerance here")


def piola_force_findings(
    split: ElementSplit, S: np.ndarray, matches: Callable[..., float]
) -> List[Finding]:
    """The wrong products of :data:`PRODUCTS`, and F transposed (for an isotropic material the
    force of S F^T), whose force alone matches the engine's:
    matches(f, None) finite (the probes near a state where the force is right, F and S diagonal
    there so that S F = F S, give forces only:
    :func:`conformance.diagnosis.hand_derived.nearby_force_reading`). S: (m, 3, 3) per cell.
    """
    F = split.F
    W, _, Vt = np.linalg.svd(F)
    R = W @ Vt  # F = R U
    candidates = [
        (
            f"piola-assembly-piola-{code}",
            f"the first Piola stress computed as {name} instead of F S in the force"
            + _VOIGT_GLOSS.get(code, ""),
            M(S, F),
            f"times F so ({name})",
        )
        for code, (name, M) in PRODUCTS.items()
        if code != "FS"
    ]
    # F^T used as F everywhere gives P = F^T S(F F^T) = F^T R S R^T for an isotropic S: the
    # same force as S F^T there, so the two are said together (ambiguous), never S F^T alone.
    candidates.append(
        (
            "piola-assembly-F-transposed",
            "the deformation gradient assembled transposed (F^T used as F everywhere: "
            "P = F^T S(F F^T), for an isotropic material the force of S F^T)",
            _t(F) @ R @ S @ _t(R),
            "rotated by R (F = R U) and multiplied by F^T, as S(F F^T) = R S R^T for an "
            "isotropic material",
        )
    )
    # a spectral engine assembling S on the eigenvectors of b = F F^T (R N_a) for those of C:
    # S' = R S R^T for an isotropic S (spectral_frames reads it on force and stiffness)
    candidates.append(
        (
            "spectral-frame-b",
            "the principal directions taken from b = F F^T (the spatial ones, n_a = R N_a) where "
            "those of C belong: the stress assembled on the eigenvectors of b",
            F @ R @ S @ _t(R),
            "rotated by R (F = R U) and multiplied by F, as S on b's eigenvectors is for an "
            "isotropic material",
        )
    )
    found = []
    for code, words, P, how in candidates:
        fe = -split.V0[:, None, None] * np.einsum("miJ,maJ->mai", P, split.D)
        left = matches(assemble(split.cells, split.n, fe, None)[0], None)
        if np.isfinite(left):
            found.append(
                Finding(
                    code,
                    words,
                    FULL,
                    "the oracle's second Piola stress per cell (from its element split) "
                    f"{how}, assembled into f_a = -V P G_a: force error {left:.1e}",
                    {"variant": code, "residual": left},
                )
            )
    return found


def piola_assembly_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the total-Lagrangian variant the
    engine matches named first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (piola_findings,))
