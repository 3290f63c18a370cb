"""A constitutive routine handed the wrong kinematics while its driver uses the true F.

An engine built around a material routine (an Abaqus UMAT: F in, Cauchy stress and spatial
tangent out) assembles, per cell, with the driver's own shape gradients grad N_a = F^-T D_a and
volume v = J V0:

    f_a = -v sigma' grad N_a,
    K_ab = v grad N_a . c' . grad N_b + v (grad N_a . sigma' grad N_b) I.

When the routine is handed F' (and a fibre frame R') in place of F (and R0), sigma' and c' are
the material's Cauchy stress and spatial tangent AT F' (with R'), used unchanged. Each variant
of :data:`ROUTINE_INPUTS` declares F', R' from F, R0:

- ``isochoric-F``: F_bar = J^(-1/3) F (a mixed u/p element's driver, whose pressure field
  carries the volume change): the volumetric response lost;
- ``right-stretch``: U = sqrt(C) (F = R U, a corotational driver's habit), the results never
  rotated back by R;
- ``F-transposed``: F^T (the deformation gradient transposed on its way to the routine);
- ``frame-corotated``: the frame rotated with the material by the polar R of F before use,
  R' = R R0, with the Lagrangian strain (Ef = (R R0)^T E (R R0) for R0^T E R0).

The material at F' comes from MJED on the case's cells exploded (each its own four nodes, its
rest shape unchanged, its positions moved so that its deformation gradient is F'): the oracle's
stand-in only where MJED's sum on the case's own mesh is the oracle's
(:func:`conformance.diagnosis.elements.element_split`), as in
:mod:`conformance.diagnosis.shape_gradients`. Nothing is fitted: a variant is named when its
force and stiffness match the engine's within the case's tolerance and differ from the oracle's
(several: ambiguous, with the assembly's own kinematic slips of
:mod:`conformance.diagnosis.spatial_assembly`, e.g. b formed as F^T F, which is the routine
given U for an isotropic material).

On a state without rotation (R = I: U = F, R R0 = R0) such an engine is right; only the force
at the kit's probes near it is wrong. :func:`probe_force_findings` gives the same variants'
forces at a probe for :func:`conformance.diagnosis.hand_derived.nearby_force_reading`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    prediction_errors,
    split_reading,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.spatial_assembly import (
    ASSEMBLY_VARIANTS,
    assemble_variant,
    assembly_matches,
    spatial_parts,
)
from conformance.diagnosis.spatial_tangent import SpatialCells
from conformance.judge.compare import Scales, Tolerances

__all__ = [
    "RoutineInput",
    "ROUTINE_INPUTS",
    "polar",
    "piola_at",
    "routine_cells",
    "SAME_PREDICTION",
    "merge_same",
    "routine_input_findings",
    "probe_force_findings",
    "spatial_kinematics_reading",
]

Frame = Optional[np.ndarray]


def polar(F: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(R, U) of F = R U (m, 3, 3 each), R the nearest rotation (SVD), U = R^T F symmetrised."""
    W, _, Vt = np.linalg.svd(F)
    R = W @ Vt
    U = R.swapaxes(1, 2) @ F
    return R, 0.5 * (U + U.swapaxes(1, 2))


@dataclass(frozen=True)
class RoutineInput:
    """code; words: the mistake; given(F (m, 3, 3), R0 (m, 3, 3) or None) -> (F', R'): what the
    routine is handed; frame: the variant needs a fibre frame (it changes only the frame).
    """

    code: str
    words: str
    given: Callable[[np.ndarray, Frame], Tuple[np.ndarray, Frame]]
    frame: bool = False


_DRIVER = "the driver's shape gradients and volume from the true F"

#: The substitutions tried, each predicting sigma' = sigma(F', R') and c' = c(F', R').
ROUTINE_INPUTS: Tuple[RoutineInput, ...] = (
    RoutineInput(
        "isochoric-F",
        "the constitutive routine handed the isochoric deformation gradient F_bar = J^(-1/3) F "
        "instead of F (a mixed u/p element's driver, whose pressure field carries the volume "
        f"change): the volumetric stress and tangent lost; {_DRIVER}",
        lambda F, R: (np.cbrt(np.linalg.det(F))[:, None, None] ** -1.0 * F, R),
    ),
    RoutineInput(
        "right-stretch",
        "the constitutive routine handed the right stretch tensor U = sqrt(C) instead of F "
        "(F = R U, R the polar rotation; a corotational driver's habit) and its stress and "
        "tangent used without rotating them by R (R sigma R^T): right only where the cells do "
        f"not rotate; {_DRIVER}",
        lambda F, R: (polar(F)[1], R),
    ),
    RoutineInput(
        "F-transposed",
        "the constitutive routine handed F^T for F (the deformation gradient transposed on its "
        f"way in, a row/column-major slip); {_DRIVER}",
        lambda F, R: (np.ascontiguousarray(F.swapaxes(1, 2)), R),
    ),
    RoutineInput(
        "frame-corotated",
        "the fibre frame rotated with the material by the polar rotation R of F = R U before "
        "use (R R0 for the frame R0, as a corotational orientation) while the routine works "
        "with the Lagrangian strain: Ef = (R R0)^T E (R R0) instead of R0^T E R0",
        lambda F, R: (F, None if R is None else polar(F)[0] @ R),
        frame=True,
    ),
)


def _cell_frames(model: Any, m: int) -> Frame:
    """The model's frame per cell (m, 3, 3), or None (no frame)."""
    frame = getattr(model, "frame", None)
    if frame is None:
        return None
    R = np.asarray(frame, dtype=np.float64)
    return np.broadcast_to(R, (m, 3, 3)).copy() if R.ndim == 2 else R.reshape(m, 3, 3)


def piola_at(
    model: Any,
    points: np.ndarray,
    split: ElementSplit,
    F2: np.ndarray,
    frame2: Frame = None,
    stiffness: bool = True,
) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """(P (m, 3, 3), A = dP/dF (m, 3, 3, 3, 3); zeros without ``stiffness``): the material's
    first Piola stress and its derivative at F2 (m, 3, 3) with the frame ``frame2`` (m, 3, 3;
    None: the model's own), from MJED on the split's cells exploded (each its own four nodes,
    its rest shape unchanged, moved so that its deformation gradient is F2); None where MJED
    cannot (not its material, F2 not invertible).
    """
    import mjed

    cells = split.cells
    m = cells.shape[0]
    J2 = np.linalg.det(F2)
    if np.any(~np.isfinite(J2)) or np.any(J2 <= 0.0):
        return None
    if frame2 is not None:
        try:
            model = dataclasses.replace(model, frame=frame2)
        except (TypeError, ValueError):
            return None
    X = points[cells]  # (m, 4, 3)
    x = X[:, :1] + np.einsum("mij,maj->mai", F2, X - X[:, :1])
    local = np.arange(4 * m, dtype=np.int64).reshape(m, 4)
    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), local), model)
        fe = np.asarray(field.element_forces(x.reshape(-1, 3)), dtype=np.float64)
        Ke = (
            np.asarray(field.element_stiffness(x.reshape(-1, 3)), dtype=np.float64)
            if stiffness
            else np.zeros((m, 12, 12))
        )
    except Exception:  # noqa: BLE001 - not an MJED material, or not at this state
        return None
    return cell_piola(ElementSplit(local, 4 * m, split.V0, split.D, F2, fe, Ke, 0.0))


def routine_cells(
    model: Any,
    points: np.ndarray,
    split: ElementSplit,
    F2: np.ndarray,
    frame2: Frame,
    stiffness: bool = True,
) -> Optional[Tuple[np.ndarray, Optional[np.ndarray]]]:
    """(sigma (m, 3, 3), c (m, 3, 3, 3, 3) or None without ``stiffness``): the material's Cauchy
    stress and spatial tangent at F2 (m, 3, 3) with the frame ``frame2`` (m, 3, 3; None: the
    model's own), from MJED on the split's cells exploded (:func:`piola_at`); None where MJED
    cannot (not its material, F2 not invertible, a value not finite).
    """
    at = piola_at(model, points, split, F2, frame2, stiffness)
    if at is None:
        return None
    P, A = at
    J2 = np.linalg.det(F2)
    Jv = J2[:, None, None]
    if not stiffness:
        S = np.linalg.solve(F2, P)
        S = 0.5 * (S + S.swapaxes(1, 2))
        sigma = F2 @ S @ F2.swapaxes(1, 2) / Jv
        return (sigma, None) if np.all(np.isfinite(sigma)) else None
    t = cell_tensors(P, A, F2)
    sigma = F2 @ t.S @ F2.swapaxes(1, 2) / Jv
    c = np.einsum("miI,mjJ,mkK,mlL,mIJKL->mijkl", F2, F2, F2, F2, t.CC, optimize=True)
    c = c / J2[:, None, None, None, None]
    if not (np.all(np.isfinite(sigma)) and np.all(np.isfinite(c))):
        return None
    return sigma, c


def _variants(model: Any, split: ElementSplit) -> List[Tuple[RoutineInput, np.ndarray, Frame]]:
    """(variant, F', R') of each routine input that applies to ``model`` (a frame variant only
    with a frame) and changes what the routine is handed.
    """
    R0 = _cell_frames(model, split.cells.shape[0])
    out = []
    for v in ROUTINE_INPUTS:
        if v.frame and R0 is None:
            continue
        F2, R2 = v.given(split.F, R0)
        same_F = np.allclose(F2, split.F, rtol=0.0, atol=1e-14)
        same_R = R2 is None or np.allclose(R2, R0, rtol=0.0, atol=1e-14)
        if not (same_F and same_R):
            out.append((v, F2, R2 if v.frame else None))
    return out


#: Two predictions whose force and stiffness differ by less than this (relative) are one
#: prediction: the same mistake said two ways (for an isotropic material the routine handed U,
#: handed F^T, and b formed as F^T F all give R^T sigma R), round-off apart; any two different
#: mistakes differ by far more (1e-4 and up).
SAME_PREDICTION = 1e-10


def _same(a: tuple, b: tuple) -> bool:
    """Whether predictions a, b (force (n, 3), stiffness or None) are one
    (:data:`SAME_PREDICTION`).
    """

    def close(x, y, norm):
        return norm(x - y) <= SAME_PREDICTION * max(norm(x), norm(y), 1e-300)

    if not close(a[0], b[0], np.linalg.norm):
        return False
    if a[1] is None or b[1] is None:
        return True
    return close(sp.csr_matrix(a[1]), sp.csr_matrix(b[1]), sparse_norm)


def merge_same(found: List[Tuple[Finding, tuple]]) -> List[Finding]:
    """(finding, its prediction (f, K or None)) -> the findings, those whose predictions are one
    (:func:`_same`) merged into the first: one mistake, its other readings said beside it.
    """
    groups: List[List[Tuple[Finding, tuple]]] = []
    for item in found:
        for g in groups:
            if _same(g[0][1], item[1]):
                g.append(item)
                break
        else:
            groups.append([item])
    out = []
    for g in groups:
        first = g[0][0]
        if len(g) > 1:
            others = "; ".join(x.title for x, _ in g[1:])
            first = dataclasses.replace(
                first,
                title=f"{first.title} (the same force and stiffness, to round-off, as: {others})",
                figures={**first.figures, "same_as": [x.code for x, _ in g[1:]]},
            )
        out.append(first)
    return out


def _routine_predictions(
    model: Any, points: np.ndarray, split: ElementSplit, stiffness: bool = True
) -> List[Tuple[RoutineInput, np.ndarray, Optional[sp.csr_matrix]]]:
    """(variant, force (n, 3), stiffness or None) of each routine input of ``model`` that MJED
    can evaluate, assembled with the true spatial gradients and volume.
    """
    parts = spatial_parts(split)
    right = next(v for v in ASSEMBLY_VARIANTS if v.code == "right")
    out = []
    for v, F2, R2 in _variants(model, split):
        with np.errstate(all="ignore"):
            at = routine_cells(model, points, split, F2, R2, stiffness)
            if at is None:
                continue
            if stiffness:
                cells = SpatialCells(at[0], at[1], parts.cells.gN, parts.cells.v)
                fv, Kv = assemble_variant(split, dataclasses.replace(parts, cells=cells), right)
            else:
                fe = -parts.cells.v[:, None, None] * np.einsum(
                    "mkp,map->mak", at[0], parts.cells.gN
                )
                fv, Kv = assemble(split.cells, split.n, fe, None)
        out.append((v, fv, Kv))
    return out


def routine_input_findings(
    model: Any,
    points: np.ndarray,
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Tuple[Finding, tuple]]:
    """The routine inputs of :data:`ROUTINE_INPUTS` whose assembly matches the engine's force f
    (n, 3) and stiffness K within ``tol`` and differs from the oracle's (the split's), each with
    its prediction (force, stiffness); neither merged nor said as ambiguous yet.
    """
    how = (
        "the material's stress and tangent evaluated at what the routine is handed (MJED, "
        f"whose sum is the oracle's to {split.residual:.1e} on this case, on the cells so "
        "deformed), assembled with the true spatial gradients and volume"
    )
    found = []
    for v, fv, Kv in _routine_predictions(model, points, split):
        e = prediction_errors(split, f, K, (fv, Kv), s, tol)
        if e is None:
            continue
        left = f"force error {e.force:.1e}, stiffness error {e.stiffness:.1e}"
        figures = {"variant": v.code, "residual": max(e.force, e.stiffness)}
        finding = Finding(f"routine-input-{v.code}", v.words, FULL, f"{how}: {left}", figures)
        found.append((finding, (fv, Kv)))
    return found


def probe_force_findings(
    model: Any, points: np.ndarray, split: ElementSplit, matches: Callable[..., float]
) -> List[Finding]:
    """The routine inputs and the spatial assembly's kinematic variants whose force alone
    matches: matches(f, None) finite (the probes near a state where the force is right;
    :func:`conformance.diagnosis.hand_derived.nearby_force_reading`); those with one force
    merged (:func:`merge_same`). ``split``: the oracle's at the probe.
    """
    parts = spatial_parts(split)
    candidates = []
    for v in ASSEMBLY_VARIANTS:
        if v.code == "right" or v.code.startswith("geometric"):
            continue  # the geometric stiffness does not reach the force
        with np.errstate(all="ignore"):
            fv, _ = assemble_variant(split, parts, v)
        candidates.append((f"spatial-assembly-{v.code}", v.words, fv))
    for v, fv, _ in _routine_predictions(model, points, split, stiffness=False):
        candidates.append((f"routine-input-{v.code}", v.words, fv))
    found = []
    for code, words, fv in candidates:
        left = matches(fv, None)
        if np.isfinite(left):
            evidence = (
                "the force of this mistake (the oracle's per-cell stress, or the material at "
                "what the routine is handed, assembled with the engine's kinematics): error "
                f"against your engine's {left:.1e}"
            )
            found.append((Finding(code, words, FULL, evidence, {"residual": left}), (fv, None)))
    return merge_same(found)


def spatial_kinematics_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the updated-Lagrangian kinematic
    mistakes the engine matches named first: the assembly's
    (:func:`conformance.diagnosis.spatial_assembly.assembly_matches`) and the routine's inputs,
    compared together (one prediction said several ways: merged; several: ambiguous).
    """

    def finder(split, f, K, s, tol):
        parts = spatial_parts(split)
        by_code = {f"spatial-assembly-{v.code}": v for v in ASSEMBLY_VARIANTS}
        found = [
            (x, assemble_variant(split, parts, by_code[x.code]))
            for x in assembly_matches(split, f, K, s, tol)
        ]
        found += routine_input_findings(ci.model, ci.points, split, f, K, s, tol)
        return ambiguous(merge_same(found), "their predictions differ by less than the tolerance")

    return split_reading(diag, ci, out, ref, s, (finder,))
