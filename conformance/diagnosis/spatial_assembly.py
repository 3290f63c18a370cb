"""An updated-Lagrangian assembly with the wrong shape gradients, volume or geometric stress.

An updated-Lagrangian engine writes the Cauchy stress sigma and the spatial tangent c and
integrates over the deformed volume v = J V with the spatial shape gradients grad N_a = F^-T D_a
(the row form D F^-1):

    f_a = -v sigma grad N_a,   K_ab = v grad N_a . c . grad N_b + v (grad N_a . sigma grad N_b) I.

Its mistakes in the kinematics of the assembly are tested here, per cell, on the oracle's answer:
sigma = F S F^T / J and c = F F F F : CC / J come from the oracle's element split (its per-cell
S and CC, :func:`conformance.diagnosis.invariant_pieces.cell_tensors`, pushed forward by
:func:`conformance.diagnosis.spatial_tangent.spatial_cells`), and each variant reassembles them
with

- another gradient everywhere: F^-1 D_a (the row form D F^-T, the inverse transposed once too
  often), D_a itself (the reference gradients), or D_a multiplied by F where F^-1 belongs (the
  row forms D F and D F^T);
- only the geometric stiffness changed: built with the reference gradients D_a or with
  F^-1 D_a, or with the pressure part of sigma alone (tr(sigma)/3 I).

(The volume itself confused, a factor J_c^q on the force and J_c^p on the stiffness, is
:mod:`conformance.diagnosis.volumes`.) A variant is named when its force and stiffness match
the engine's within the case's tolerance and no other does (several: ambiguous). The correct
variant must reproduce the oracle (a check that the reading is sound on this case: otherwise
nothing is claimed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola, split_reading
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.spatial_tangent import SpatialCells, spatial_cells
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "SpatialParts",
    "spatial_parts",
    "AssemblyVariant",
    "ASSEMBLY_VARIANTS",
    "assemble_variant",
    "assembly_findings",
    "assembly_matches",
    "spatial_assembly_reading",
]


@dataclass(frozen=True)
class SpatialParts:
    """Per cell: the oracle's spatial quantities (sigma, c, the right gradients grad N_a =
    F^-T D_a and v = J V0); gT (m, 4, 3) F^-1 D_a, D (m, 4, 3) the reference gradients, gF
    (m, 4, 3) the row form D F and gFT the row form D F^T: the gradients of the mistakes.
    """

    cells: SpatialCells
    gT: np.ndarray
    D: np.ndarray
    gF: np.ndarray
    gFT: np.ndarray


def spatial_parts(split: ElementSplit) -> SpatialParts:
    """The oracle's per-cell sigma and c, and the gradients, from its element split."""
    t = cell_tensors(*cell_piola(split), split.F)
    gT = np.einsum("mpi,mai->map", np.linalg.inv(split.F), split.D)  # F^-1 D_a
    gF = split.D @ split.F  # rows D_a F (F^T D_a)
    gFT = split.D @ split.F.swapaxes(1, 2)  # rows D_a F^T (F D_a)
    return SpatialParts(spatial_cells(split, t.S, t.CC), gT, split.D, gF, gFT)


@dataclass(frozen=True)
class AssemblyVariant:
    """code; words: the mistake; which gradient (g, gT, D) the force and material stiffness use;
    geo_grad: the geometric stiffness's gradient; pressure: the geometric stress is tr(sigma)/3 I
    alone; rotated: sigma and c computed from C where b belongs (R^T sigma R, c rotated by R^T,
    F = R U), as an engine that forms b = F^T F or reads F transposed gets them.
    """

    code: str
    words: str
    grad: str = "g"
    geo_grad: str = "g"
    pressure: bool = False
    rotated: bool = False


_RIGHT = "grad N_a = F^-T D_a (the row form D F^-1)"

#: The variants tested (the first is the correct assembly: a soundness check, never named).
ASSEMBLY_VARIANTS: Tuple[AssemblyVariant, ...] = (
    AssemblyVariant("right", "the correct spatial assembly"),
    AssemblyVariant(
        "gradient-F-inverse",
        f"spatial shape gradients F^-1 D_a (the row form D F^-T, the inverse of F transposed) "
        f"where {_RIGHT} belongs, in the force and the stiffness",
        grad="gT",
        geo_grad="gT",
    ),
    AssemblyVariant(
        "gradient-reference",
        f"reference shape gradients D_a (dN/dX) used with the Cauchy stress where the spatial "
        f"gradients {_RIGHT} belong (the push-forward of the gradients missing), in the force "
        "and the stiffness",
        grad="D",
        geo_grad="D",
    ),
    AssemblyVariant(
        "gradient-times-F",
        f"spatial shape gradients computed as D F (dN/dX multiplied by F, F^T D_a) where "
        f"{_RIGHT} belongs (dN/dx = dN/dX dX/dx: the inverse of F missing), in the force and "
        "the stiffness",
        grad="gF",
        geo_grad="gF",
    ),
    AssemblyVariant(
        "gradient-times-F-transposed",
        f"spatial shape gradients computed as D F^T (F D_a: dN/dX multiplied by F transposed) "
        f"where {_RIGHT} belongs (the inverse of F missing), in the force and the stiffness",
        grad="gFT",
        geo_grad="gFT",
    ),
    AssemblyVariant(
        "b-from-C",
        "the left Cauchy-Green tensor formed as F^T F (that is C) where b = F F^T belongs: sigma "
        "and c built on C, i.e. R^T sigma R and c rotated back by R (F = R U)",
        rotated=True,
    ),
    AssemblyVariant(
        "F-transposed",
        "the deformation gradient assembled transposed (F^T used as F everywhere): b built as "
        "F^T F = C, so sigma and c rotated back by R (F = R U), and the spatial gradients "
        "D F^-T (F^-1 D_a)",
        grad="gT",
        geo_grad="gT",
        rotated=True,
    ),
    AssemblyVariant(
        "geometric-reference",
        "the geometric (initial-stress) stiffness built with the reference gradients D_a: "
        f"(D_a . sigma D_b) v I where {_RIGHT} belongs (force and material stiffness right)",
        geo_grad="D",
    ),
    AssemblyVariant(
        "geometric-F-inverse",
        "the geometric (initial-stress) stiffness built with F^-1 D_a (the inverse of F "
        f"transposed) where {_RIGHT} belongs (force and material stiffness right)",
        geo_grad="gT",
    ),
    AssemblyVariant(
        "geometric-pressure",
        "the geometric (initial-stress) stiffness built with the pressure tr(sigma)/3 alone, "
        "the deviatoric part of sigma dropped from grad N_a . sigma grad N_b",
        pressure=True,
    ),
)


def _rotation(F: np.ndarray) -> np.ndarray:
    """(m, 3, 3) the rotation R of the polar decomposition F = R U (by the SVD of F)."""
    W, _, Vt = np.linalg.svd(F)
    return W @ Vt


def assemble_variant(
    split: ElementSplit, parts: SpatialParts, v: AssemblyVariant
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """Force (n, 3) and stiffness (3n, 3n) of an engine that assembles sigma and c as ``v``."""
    grads = {"g": parts.cells.gN, "gT": parts.gT, "D": parts.D, "gF": parts.gF, "gFT": parts.gFT}
    G, Gg = grads[v.grad], grads[v.geo_grad]
    vol = parts.cells.v
    sigma, c = parts.cells.sigma, parts.cells.c
    if v.rotated:
        R = _rotation(split.F)
        sigma = np.einsum("mak,mab,mbl->mkl", R, sigma, R)
        c = np.einsum("mak,mbp,mcl,mdq,mabcd->mkplq", R, R, R, R, c, optimize=True)
    sig = sigma
    if v.pressure:
        sig = np.einsum("mii->m", sig)[:, None, None] / 3.0 * np.eye(3)
    fe = -vol[:, None, None] * np.einsum("mkp,map->mak", sigma, G)
    mat = np.einsum("map,mkplq,mbq->makbl", G, c, G)
    geo = np.einsum("map,mpq,mbq->mab", Gg, sig, Gg)
    Ke = mat + np.einsum("mab,kl->makbl", geo, np.eye(3))
    Ke = (vol[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    return assemble(split.cells, split.n, fe, Ke)


def assembly_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The variants of :data:`ASSEMBLY_VARIANTS` whose assembly matches the engine (several:
    ambiguous); none when the correct variant does not reproduce the split (then the per-cell
    sigma and c are not trusted).
    """
    return ambiguous(assembly_matches(split, f, K, s, tol))


def assembly_matches(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """:func:`assembly_findings` before several are said as ambiguous (for a caller that adds
    its own variants to the same comparison).
    """
    parts = spatial_parts(split)
    K = sp.csr_matrix(K)
    found = []
    for v in ASSEMBLY_VARIANTS:
        with np.errstate(all="ignore"):
            fv, Kv = assemble_variant(split, parts, v)
        e = errors(f, K, None, fv, Kv, 0.0, s)
        if v.code == "right":
            f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
            e0 = errors(f0, K0, None, fv, Kv, 0.0, s)
            if not tol.within(e0, energy=False):
                return []  # the reassembly does not reproduce the oracle: claim nothing
            continue
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    f"spatial-assembly-{v.code}",
                    v.words,
                    FULL,
                    "the oracle's Cauchy stress and spatial tangent per cell (pushed forward from "
                    f"its element split, whose sum is the oracle's to {split.residual:.1e}) "
                    f"assembled so: force error {e.force:.1e}, stiffness error {e.stiffness:.1e}",
                    {"variant": v.code, "residual": max(e.force, e.stiffness)},
                )
            )
    return found


def spatial_assembly_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the assembly variant the engine
    matches named first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    return split_reading(diag, ci, out, ref, s, (assembly_findings,))
