"""Mistakes of an updated-Lagrangian element: its spatial tangent c in a wrong form, or one part
of its element matrix in another local dof order.

An engine written with the Cauchy stress sigma, the spatial tangent c (6 x 6 Voigt), B matrices
from grad N = D F^-1 and integrals over v = J V0 computes, per cell,

    K_e = v B^T c B + v (grad N_a . sigma grad N_b) I,    f_a = -v sigma grad N_a.

From the oracle's per-cell stress and tangent (the element split's S and CC,
:mod:`conformance.diagnosis.invariant_pieces`), pushed forward by
:func:`conformance.diagnosis.spatial_tangent.spatial_cells`, c = F F F F : CC / J and
sigma = F S F^T / J are exact, so each family mistake below predicts the engine's force and
stiffness with nothing fitted:

1. **Voigt order.** c filled in Abaqus' order (xx, yy, zz, xy, xz, yz) while B uses FEBio's
   (xx, yy, zz, xy, yz, xz): the yz and xz rows and columns of c exchanged (stiffness only).
2. **Tensor shear rows in B.** B's shear rows (v_i,j + v_j,i)/2 instead of engineering shear:
   the shear rows of B halved, so the force sees sigma's shear halved and B^T c B its shear
   rows and columns halved.
3. **Objective rate.** The tangent of the Jaumann rate of the Kirchhoff stress (Abaqus UMAT's
   DDSDDE / J) used as c: c + (d_ik s_jl + s_ik d_jl + d_il s_jk + s_il d_jk) / 2 (stiffness
   only); its correction with the other sign is tested beside it, so that the sign is evidence.
   A perturbation tangent (Miehe's) that differences sigma instead of tau = J sigma is left
   with -sigma_ij delta_kl (the derivative of 1/J), a variant of the same kind.
4. **One part in another local order.** The geometric (initial-stress) block written
   kron(I3, G), component-major, inside a node-major element matrix (or the material part so
   while the geometric part is node-major): stiffness only.

A variant is named only when its prediction matches the engine within the case's tolerance and
is not the oracle's own; several that match are said as ambiguous by the caller. The numerical
variant (a perturbation tangent) may leave more, up to the round-off of its differences
(:data:`NUMERICAL`): then it is said as partly explaining, with what it leaves.
"""

from __future__ import annotations

from typing import Callable, Dict, List

import numpy as np

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, PARTIAL, Finding
from conformance.diagnosis.invariant_pieces import CellTensors
from conformance.diagnosis.spatial_tangent import SpatialCells, material_stiffness, spatial_cells

__all__ = [
    "FEBIO",
    "to_voigt",
    "from_voigt",
    "jaumann_terms",
    "TANGENT_VARIANTS",
    "PART_ORDERS",
    "spatial_variant_findings",
]

#: FEBio's Voigt order of the index pairs: xx, yy, zz, xy, yz, xz.
FEBIO = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))

_EYE = np.eye(3)


def to_voigt(c: np.ndarray) -> np.ndarray:
    """(m, 6, 6) the Voigt matrix of c (m, 3, 3, 3, 3) in :data:`FEBIO` order."""
    i = np.array([p[0] for p in FEBIO])
    j = np.array([p[1] for p in FEBIO])
    return c[:, i[:, None], j[:, None], i[None, :], j[None, :]]


def from_voigt(C6: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the minor-symmetric tensor of a Voigt matrix C6 (m, 6, 6), FEBio order:
    with engineering shear in B, B^T C6 B is this tensor contracted with grad N on both sides.
    """
    idx = np.empty((3, 3), dtype=int)
    for k, (i, j) in enumerate(FEBIO):
        idx[i, j] = idx[j, i] = k
    return C6[:, idx[:, :, None, None], idx[None, None, :, :]]


def _voigt_map(rows: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The map c -> c' whose Voigt matrix is c's with its rows and columns scaled or moved by
    ``rows`` (6, 6): C6' = R C6 R^T.
    """
    return lambda c: from_voigt(rows @ to_voigt(c) @ rows.T)


_SWAP = np.eye(6)[[0, 1, 2, 3, 5, 4]]
_HALF = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])


def jaumann_terms(sigma: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the Jaumann-rate terms (d_ik s_jl + s_ik d_jl + d_il s_jk + s_il d_jk) / 2
    of the Cauchy stresses sigma (m, 3, 3): DDSDDE less c.
    """
    d = _EYE
    terms = (
        np.einsum("ik,mjl->mijkl", d, sigma)
        + np.einsum("mik,jl->mijkl", sigma, d)
        + np.einsum("il,mjk->mijkl", d, sigma)
        + np.einsum("mil,jk->mijkl", sigma, d)
    )
    return 0.5 * terms


def _jaumann(sign: float) -> Callable[[SpatialCells], np.ndarray]:
    """The Jaumann-rate terms (:func:`jaumann_terms`), times sign."""
    return lambda t: sign * jaumann_terms(t.sigma)


#: code -> (words, the engine's c minus the right c (SpatialCells -> (m, 3, 3, 3, 3)), the
#: factor on sigma's shear in the force (1: the force right)).
TANGENT_VARIANTS: Dict[str, tuple] = {
    "voigt-abaqus-order": (
        "spatial tangent c filled in Abaqus' Voigt order (xx, yy, zz, xy, xz, yz) while B uses "
        "FEBio's (xx, yy, zz, xy, yz, xz): the yz and xz rows and columns of c exchanged in "
        "B^T c B",
        lambda t: _voigt_map(_SWAP)(t.c) - from_voigt(to_voigt(t.c)),
        1.0,
    ),
    "tensor-shear-b": (
        "B written with tensor shear rows (v_i,j + v_j,i)/2 where Voigt's engineering shear "
        "strain v_i,j + v_j,i belongs: the shear rows of B halved, so the shear part of the "
        "force is halved and B^T c B has its shear rows and columns halved",
        lambda t: _voigt_map(_HALF)(t.c) - from_voigt(to_voigt(t.c)),
        0.5,
    ),
    "jaumann": (
        "the tangent of the Jaumann rate of the Kirchhoff stress (Abaqus UMAT's DDSDDE / J: "
        "c + (d_ik sigma_jl + sigma_ik d_jl + d_il sigma_jk + sigma_il d_jk)/2) used as the "
        "spatial tangent c beside the geometric stiffness: the objective-rate correction not "
        "subtracted",
        _jaumann(1.0),
        1.0,
    ),
    "jaumann-subtracted": (
        "the Jaumann-rate terms (d_ik sigma_jl + sigma_ik d_jl + d_il sigma_jk + sigma_il "
        "d_jk)/2 subtracted from the spatial tangent c (an objective-rate correction applied "
        "to a tangent that did not carry it)",
        _jaumann(-1.0),
        1.0,
    ),
    "miehe-cauchy": (
        "a perturbation tangent (Miehe's: F moved by eps sym(e_k e_l) F) that differences the "
        "Cauchy stress sigma where the Kirchhoff stress tau = J sigma belongs (then / J): c "
        "left with a -sigma_ij delta_kl term, not symmetric",
        lambda t: -np.einsum("mij,kl->mijkl", t.sigma, _EYE),
        1.0,
    ),
}

#: The unit round-off of double precision, u = 2^-53.
U = 2.0**-53

#: Variants that are numerical tangents (differences of the stress), and the stiffness error
#: they may leave beyond the tolerance, as a fraction of the variant's own term (the stiffness
#: of that term, i.e. of the prediction less the oracle, which the data give).
#:
#: Why sqrt(u), and why relative to the term. A difference quotient of a stress computed in
#: double with step eps carries that stress's rounding (a few u |sigma|) divided by eps, in
#: every column of c. Steps in use are at least sqrt(u) (~1.1e-8, the optimal step of
#: one-sided differences; below it round-off exceeds the truncation of any scheme, the case of
#: the finite-difference-roundoff reading), so the round-off left in c is at most about
#: sqrt(u) |sigma|, and its stiffness about sqrt(u) times that of a term of sigma's size: the
#: -sigma_ij delta_kl term itself (up to factors of order one from how the rounding falls; no
#: margin is added). The truncation of central differences, (eps^2 / 6) sigma''', is within
#: this for the usual steps (1e-6 to 1e-5; at 1e-4 it is comparable). A one-sided scheme's
#: truncation, (eps / 2) sigma'', is not: with any coarse step it is far beyond this, and is
#: not claimed here (the perturbation reading of
#: :mod:`conformance.diagnosis.perturbation_differences` fits a step to it). Anything else left
#: (another mistake beside the differences) is beyond this bound unless it is below the
#: differences' own round-off, where no reading can see it.
NUMERICAL = {"miehe-cauchy": U**0.5}

#: code -> words: the part of the element matrix written in component-major order.
PART_ORDERS: Dict[str, str] = {
    "geometric": "geometric (initial-stress) element block laid out component-major, "
    "kron(I3, G) instead of kron(G, I3), inside the node-major element matrix",
    "material": "material element block (B^T c B v) laid out component-major while the "
    "geometric block and the scatter are node-major",
}

#: Local dof i of a component-major 12-vector (i = 4 c + a) holds node-major dof 3 a + c.
_COMP_MAJOR = (3 * np.arange(4)[None, :] + np.arange(3)[:, None]).ravel()


def _material_part(t: SpatialCells, dc: np.ndarray) -> np.ndarray:
    """(m, 12, 12) v grad N_a . dc . grad N_b, node-major (local dof 3 a + i)."""
    Km = np.einsum("m,maj,mijkl,mbl->maibk", t.v, t.gN, dc, t.gN, optimize=True)
    return Km.reshape(-1, 12, 12)


def _shear_force(split: ElementSplit, t: SpatialCells, factor: float) -> np.ndarray:
    """(m, 4, 3) the element forces with sigma's off-diagonal scaled by ``factor``."""
    off = t.sigma - np.einsum("mii->mi", t.sigma)[:, :, None] * _EYE
    dfe = -(factor - 1.0) * np.einsum("m,mij,maj->mai", t.v, off, t.gN)
    return split.fe + dfe


def spatial_variant_findings(
    split: ElementSplit,
    cells: CellTensors,
    matches: Callable[..., float],
    tolerance: float = 0.0,
) -> List[Finding]:
    """The spatial-tangent variants and part orders whose prediction matches the engine.

    cells: the oracle's per-cell stress S (m, 3, 3) and material tangent CC (m, 3, 3, 3, 3);
    matches(f, K, allowance): the engine's error against the prediction, inf unless within
    tolerance (a numerical variant: within its allowance of :data:`NUMERICAL`, a fraction of the
    prediction's own distance from the oracle) and the prediction differs from the oracle's (as
    in :mod:`conformance.diagnosis.hand_derived`); tolerance: the case's stiffness tolerance (a
    numerical variant beyond it is partial, and says what it leaves).
    """
    t = spatial_cells(split, cells.S, cells.CC)
    found = []
    for code, (words, dc, shear) in TANGENT_VARIANTS.items():
        Ke = split.Ke + _material_part(t, dc(t))
        fe = split.fe if shear == 1.0 else _shear_force(split, t, shear)
        left = matches(*assemble(split.cells, split.n, fe, Ke), NUMERICAL.get(code, 0.0))
        if np.isfinite(left):
            numerical = left > tolerance
            found.append(
                Finding(
                    f"spatial-{code}",
                    words,
                    PARTIAL if numerical else FULL,
                    "the oracle's per-cell stress and tangent pushed forward (sigma, c = "
                    "F F F F : CC / J, grad N = D F^-1, v = J V0), the element matrices "
                    f"rebuilt so: errors against your engine {left:.1e}"
                    + (
                        f", beyond the tolerance {tolerance:.0e}: not fully explained; what is "
                        f"left is below sqrt(u) = {NUMERICAL[code]:.1e} times this term's own "
                        "stiffness, the round-off that differences of the stress at a step of "
                        "sqrt(u) or more leave"
                        if numerical
                        else ""
                    ),
                    {"variant": code, "residual": left},
                )
            )
    # v grad N_a . sigma grad N_b = V0 D_a . S D_b: the geometric block the material way.
    geo = split.Ke - material_stiffness(split, cells.S)
    for part, words in PART_ORDERS.items():
        moved = geo if part == "geometric" else split.Ke - geo
        Ke = split.Ke - moved + moved[:, _COMP_MAJOR][:, :, _COMP_MAJOR]
        left = matches(*assemble(split.cells, split.n, split.fe, Ke))
        if np.isfinite(left):
            found.append(
                Finding(
                    f"element-part-order-{part}",
                    f"element dofs in another local order (one part only): {words}",
                    FULL,
                    "the oracle's element matrices split into the geometric part (from its "
                    "per-cell stress) and the rest, that part reordered so and assembled: "
                    f"errors against your engine {left:.1e}",
                    {"part": part, "residual": left},
                )
            )
    return found
