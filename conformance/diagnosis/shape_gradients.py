"""Shape-function gradients built wrongly inside the element: the engine's D_a are not the rows
of M^-1 (M: the cell's rest edge matrix, columns X_a - X_0), e.g. its columns (M^-T, the
inverse or the edge matrix transposed).

Gradients that do not sum to zero belong to no rest cell: node 0's gradient, which an engine
forms from the others as D_0 = -(D_1 + D_2 + D_3) (the partition of unity), with its minus
lost, left out, or one term missing, and gradients built from the current positions
(:data:`GRADIENT_SLIPS`). Such an engine forms
F' = sum_a x_a D'_a^T (no longer blind to a translation), and its force -V0 P(F') D'_a and
matrix V0 D'_a . A(F') . D'_b; the material at F' comes from MJED on the cells exploded
(:func:`conformance.diagnosis.routine_inputs.piola_at`; a cell F' inverts is read as an engine
that forms its energy from C does), nothing fitted.

An engine that uses D'_a (a = 1..3, D'_0 = -sum) for both F = sum_a x_a D'_a^T and its force
-V0 P D'_a is a correct engine on a cell whose rest edges are the columns of M' with rows of
M'^-1 = D': for the transposed gradients, M' = M^T. So the hypothesis is tested exactly by
MJED on an exploded mesh (each cell its own four nodes, rest edges M', positions unchanged),
assembled with the case's cells; MJED is used only where its sum on the case's own mesh is the
oracle's (:func:`conformance.diagnosis.elements.element_split`). Cost: one MJED evaluation on
4 m nodes, vectorised.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_kinematics,
    element_split,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.routine_inputs import piola_at
from conformance.judge.compare import Scales, Tolerances, errors, grown

__all__ = [
    "REST_EDGES",
    "HYPOTHESES",
    "permuted_edges",
    "exploded_output",
    "shape_gradient_findings",
    "GRADIENT_SCALES",
    "GRADIENT_SLIPS",
    "GradientOutput",
    "gradient_output",
    "gradient_slip_findings",
    "shape_gradient_reading",
]

#: code -> (words, M -> M'): the rest edge matrix (m, 3, 3) an engine's gradients belong to.
REST_EDGES: dict = {
    "gradients-transposed": (
        "shape-function gradients transposed: D_a taken from the columns of the inverse rest "
        "edge matrix M^-1 instead of its rows (M^-T for M^-1)",
        lambda M: np.swapaxes(M, 1, 2),
    ),
}


def _edge_from(c: int, j: int) -> Callable[[np.ndarray], np.ndarray]:
    """M -> M' with rest edge c (1..3, the column X_c - X_0) written X_c - X_j (j = 1..3, not c):
    a copy slip in the edge list. Its determinant is M's (a column minus another), so the
    engine's V0 is right and only its gradients and F are not.
    """

    def edges(M: np.ndarray) -> np.ndarray:
        Mp = M.copy()
        Mp[:, :, c - 1] = M[:, :, c - 1] - M[:, :, j - 1]
        return Mp

    return edges


REST_EDGES.update(
    {
        f"rest-edge-{c}-from-node-{j}": (
            f"rest edge matrix with its edge {c} written X_{c} - X_{j} where X_{c} - X_0 belongs "
            "(a copy slip in the edge list: the volume right, every shape-function gradient and "
            "F wrong)",
            _edge_from(c, j),
        )
        for c in (1, 2, 3)
        for j in (1, 2, 3)
        if j != c
    }
)

#: Mirror of the rest coordinates (x -> -x): a rest cell whose nodes were permuted by an odd
#: permutation is inverted; mirrored it is a valid cell, and an isotropic energy (or one whose
#: frame is mirrored with it) does not change: W(F Q) = W(F) for every orthogonal Q.
MIRROR = np.diag([-1.0, 1.0, 1.0])


def permuted_edges(perm: Tuple[int, ...]) -> Callable[[np.ndarray], np.ndarray]:
    """M -> M' for gradients assigned to the nodes in another order: node a given the gradient
    of node perm[a]. Those are the gradients of the cell whose local node a rests at X_perm[a],
    so M' has columns X_perm[a] - X_perm[0] (a = 1, 2, 3); it is mirrored (:data:`MIRROR`) when
    perm is odd, which the MJED model is then told (:func:`exploded_output`, ``mirrored``).
    """
    p = np.asarray(perm)

    def edges(M: np.ndarray) -> np.ndarray:
        E = np.concatenate([np.zeros(M.shape[:2] + (1,)), M], axis=2)  # X_a - X_0, a = 0..3
        Mp = E[:, :, p[1:]] - E[:, :, p[:1]]
        return MIRROR @ Mp if _odd(perm) else Mp

    return edges


def _odd(perm: Tuple[int, ...]) -> bool:
    """Whether ``perm`` is an odd permutation (inversions counted)."""
    return sum(a > b for a, b in itertools.combinations(perm, 2)) % 2 == 1


def _permutation_hypotheses() -> dict:
    """The 23 non-identity node orders of a tetrahedron: code -> (words, edges, mirrored)."""
    out = {}
    for perm in itertools.permutations(range(4)):
        if perm == (0, 1, 2, 3):
            continue
        code = "gradients-node-order-" + "".join(map(str, perm))
        words = (
            "shape-function gradients assigned to the cell's nodes in another order: the "
            f"gradients of local nodes {perm} stored for nodes (0, 1, 2, 3) (a local node "
            "permutation, e.g. a reference element with its origin at another node)"
        )
        out[code] = (words, permuted_edges(perm), _odd(perm))
    return out


#: code -> (words, M -> M', mirrored): every hypothesis tried, the transposed gradients first.
HYPOTHESES: dict = {
    **{k: (w, e, False) for k, (w, e) in REST_EDGES.items()},
    **_permutation_hypotheses(),
}


def exploded_output(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    positions: np.ndarray,
    edges: Callable[[np.ndarray], np.ndarray],
    mirrored: bool = False,
    keep_force: Optional[Callable[[np.ndarray], bool]] = None,
) -> Optional[Tuple[np.ndarray, sp.csr_matrix]]:
    """Force (n, 3) and stiffness of MJED with each cell's rest edge matrix M (m, 3, 3), columns
    X_a - X_0, replaced by edges(M), assembled on ``cells`` (m, 4); None when MJED cannot (no
    such material, or a cell of edges(M) not positively oriented). mirrored: edges(M) holds
    mirrored rest coordinates (:data:`MIRROR`), so a material frame is mirrored too.
    keep_force(f) -> False: None as well, before the element matrices are computed (the
    costly part, for a hypothesis whose force already rules it out).
    """
    import mjed

    if mirrored and getattr(model, "frame", None) is not None:
        from dataclasses import replace

        model = replace(model, frame=MIRROR @ np.asarray(model.frame))

    m = cells.shape[0]
    X = points[cells]
    M = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)  # columns: the three rest edges
    Mp = edges(M)
    if np.any(np.linalg.det(Mp) <= 0):
        return None
    rest = np.concatenate([np.zeros((m, 1, 3)), np.swapaxes(Mp, 1, 2)], axis=1).reshape(-1, 3)
    local = np.arange(4 * m, dtype=np.int64).reshape(m, 4)
    try:
        field = mjed.make_force_field(mjed.TetMesh(rest, local), model)
        x = positions[cells].reshape(-1, 3)
        fe = np.asarray(field.element_forces(x), dtype=np.float64)
        if keep_force is not None and not keep_force(assemble(cells, points.shape[0], fe, None)[0]):
            return None
        Ke = np.asarray(field.element_stiffness(x), dtype=np.float64)
    except Exception:  # noqa: BLE001 - not an MJED material, or not at this state: no reading
        return None
    f, K = assemble(cells, points.shape[0], fe, Ke)
    return f, K


def shape_gradient_findings(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The mistaken gradients of :data:`HYPOTHESES` whose output matches the engine's (several:
    ambiguous); ``split`` vouches that MJED is the oracle on this case.
    """
    f = np.asarray(f, dtype=np.float64)

    def near(fh: np.ndarray) -> bool:  # a loose screen on the force (the test is below)
        scale = max(s.force, float(np.linalg.norm(fh)), float(np.linalg.norm(f)))
        d = min(np.linalg.norm(f - fh), np.linalg.norm(f + fh))
        return bool(d <= 1e3 * tol.force * scale)

    found = []
    for code, (words, edges, mirrored) in HYPOTHESES.items():
        with np.errstate(all="ignore"):
            out = exploded_output(model, points, split.cells, positions, edges, mirrored, near)
        if out is None:
            continue
        # An odd order inverts the cell: an engine taking its rest volume from the same edges
        # (det / 6, no absolute value) has it negative, force and stiffness with it.
        for sign in (1.0, -1.0) if mirrored else (1.0,):
            fh, Kh = sign * out[0], sign * out[1]
            e = errors(f, sp.csr_matrix(K), None, fh, Kh, 0.0, grown(s, fh, Kh))
            if not tol.within(e, energy=False):
                continue
            found.append(
                Finding(
                    code + ("-negative-volume" if sign < 0 else ""),
                    words
                    + (
                        "; the rest volume taken from those edges, det / 6, is negative for "
                        "this order, and force and stiffness change sign with it"
                        if sign < 0
                        else ""
                    ),
                    FULL,
                    "MJED (whose sum is the oracle's to "
                    f"{split.residual:.1e} on this case) on cells rebuilt with the rest edges "
                    f"those gradients belong to: force error {e.force:.1e}, stiffness error "
                    f"{e.stiffness:.1e}",
                    {"residual": max(e.force, e.stiffness)},
                )
            )
    return ambiguous(
        found or _scaled_gradient_findings(split, model, points, positions, f, K, s, tol)
    )


#: Factor -> how an engine gets its shape-function gradients that many times too large: D_a =
#: A_a n_a / (3 V0) with the face's area vector a full cross product (the 1/2 of a triangle's
#: area lost: 2), the gradients of a reference element scaled for another (1/2, 3, 1/3, 6, 1/6:
#: a volume with 1/6 for 1/2, or back).
GRADIENT_SCALES: Dict[float, str] = {
    2.0: "twice the right ones (e.g. each face's area vector taken as the full cross product of "
    "its edges, the 1/2 of a triangle's area lost, in D_a = A_a n_a / (3 V0))",
    0.5: "half the right ones (e.g. a face's area vector halved twice)",
    3.0: "three times the right ones (e.g. a volume with 1/6 for 1/2 in the divisor)",
    1.0 / 3.0: "a third of the right ones (e.g. a volume with 1/2 for 1/6 in the divisor)",
    6.0: "six times the right ones (the rest volume's 1/6 lost in the divisor)",
    1.0 / 6.0: "a sixth of the right ones (a 1/6 applied twice)",
}


def _scaled_gradient_findings(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """Every gradient D_a scaled by one factor k, the rest volume right: F' = k F (not I at
    rest), force -V0 P(k F) k D_a, matrix V0 k^2 D_a . A(k F) . D_b. MJED on cells whose rest
    edges are M / k has exactly those gradients and the volume V0 / k^3, so its output times
    k^3 is the engine's, nothing fitted.
    """
    found = []
    for k, words in GRADIENT_SCALES.items():
        with np.errstate(all="ignore"):
            out = exploded_output(
                model,
                points,
                split.cells,
                positions,
                lambda M, k=k: M / k,
                keep_force=lambda fh, k=k: bool(
                    np.linalg.norm(f - k**3 * fh)
                    <= 1e3 * tol.force * max(s.force, float(np.linalg.norm(f)))
                ),
            )
        if out is None:
            continue
        fh, Kh = k**3 * out[0], k**3 * out[1]
        e = errors(f, sp.csr_matrix(K), None, fh, Kh, 0.0, grown(s, fh, Kh))
        if not tol.within(e, energy=False):
            continue
        found.append(
            Finding(
                "gradients-scaled",
                f"shape-function gradients (the shape vectors D_a) {words}, the rest volume "
                f"right: F = {k:.3g} F_true (not the identity at rest)",
                FULL,
                f"MJED (whose sum is the oracle's to {split.residual:.1e} on this case) on cells "
                f"with rest edges M / {k:.3g}, whose gradients those are, its output times "
                f"{k**3:.4g} for their volume: force error {e.force:.1e}, stiffness error "
                f"{e.stiffness:.1e}",
                {"residual": max(e.force, e.stiffness), "factor": k},
            )
        )
    return found


#: (split, x) -> (D' (m, 4, 3), V' (m,), F' (m, 3, 3) or None: sum_a x_a D'_a^T).
Formed = Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]
Gradients = Callable[[ElementSplit, np.ndarray], Formed]


def _node_zero(weights: Tuple[float, float, float]) -> Gradients:
    """Node 0's gradient written sum_b weights[b - 1] D_b (b = 1..3), the other three and the
    rest volumes right.
    """

    def gradients(split: ElementSplit, x: np.ndarray) -> Formed:
        D = split.D.copy()
        D[:, 0] = np.einsum("b,mbi->mi", np.asarray(weights), split.D[:, 1:])
        return D, split.V0, None

    return gradients


def _current(volume: bool) -> Gradients:
    """The gradients of the deformed cells (their edge matrices at x inverted); the volumes the
    rest ones, or (``volume``) the deformed ones too.
    """

    def gradients(split: ElementSplit, x: np.ndarray) -> Formed:
        v, D, _ = cell_kinematics(x, split.cells, x)
        return D, (v if volume else split.V0), None

    return gradients


def _identity_plus_positions(split: ElementSplit, x: np.ndarray) -> Formed:
    """(D, V0, I + F): the gradient of the positions taken for that of the displacements."""
    return split.D, split.V0, np.eye(3) + split.F


def _assembly_only(node_zero_from_columns: bool, transposed: bool) -> Gradients:
    """F right (formed from the right gradients, as F = Ds M^-1), the force and matrix built
    with other gradients: the columns of M^-1 for its rows (``transposed``), and node 0's
    gradient the minus sum of those columns (``node_zero_from_columns``: a sum over the wrong
    axis of M^-1) or of the gradients used.
    """

    def gradients(split: ElementSplit, x: np.ndarray) -> Formed:
        rows = split.D[:, 1:]  # [m, b, i] = (M^-1)_bi
        cols = np.swapaxes(rows, 1, 2)  # [m, b, i] = (M^-1)_ib
        D = split.D.copy()
        if transposed:
            D[:, 1:] = cols
        D[:, 0] = -(cols if node_zero_from_columns else D[:, 1:]).sum(axis=1)
        return D, split.V0, split.F

    return gradients


#: code -> (words, :data:`Gradients`): the gradients (and volumes) an engine uses for F, its
#: force and its matrix in place of the rest ones, and the F' it forms where that is not
#: sum_a x_a D'_a^T.
GRADIENT_SLIPS: Dict[str, Tuple[str, Gradients]] = {
    "gradient-0-sign": (
        "the shape-function gradient of local node 0 written D_1 + D_2 + D_3, its minus lost "
        "(the partition of unity gives D_0 = -(D_1 + D_2 + D_3)): F, force and stiffness wrong",
        _node_zero((1.0, 1.0, 1.0)),
    ),
    "gradient-0-missing": (
        "the shape-function gradient of local node 0 left zero (never formed from the partition "
        "of unity D_0 = -(D_1 + D_2 + D_3)): node 0 left out of F, force and stiffness",
        _node_zero((0.0, 0.0, 0.0)),
    ),
    **{
        f"gradient-0-without-{b}": (
            f"the shape-function gradient of local node 0 written without D_{b} (the partition "
            f"of unity D_0 = -(D_1 + D_2 + D_3) with one term lost)",
            _node_zero(tuple(0.0 if k == b else -1.0 for k in (1, 2, 3))),
        )
        for b in (1, 2, 3)
    },
    "gradients-current": (
        "shape-function gradients computed from the current positions instead of the rest "
        "configuration (the deformed edge matrix inverted, e.g. an init() run after the state "
        "is loaded), the rest volumes kept: F = I in every cell, so the force is the rest "
        "state's (zero) and the stiffness the rest tangent on the deformed cells",
        _current(volume=False),
    ),
    "gradients-current-volume": (
        "shape-function gradients and cell volumes computed from the current positions instead "
        "of the rest configuration (e.g. an init() run after the state is loaded): F = I in "
        "every cell, so the force is the rest state's (zero) and the stiffness the rest tangent "
        "on the deformed cells",
        _current(volume=True),
    ),
    "assembly-gradients-transposed": (
        "the gradient operator dF/dx of the force and stiffness (the B matrix) built from the "
        "columns of the inverse rest edge matrix M^-1 where its rows belong, while F = Ds M^-1 "
        "is right: force and stiffness not those of the engine's own F (nor its energy's)",
        _assembly_only(node_zero_from_columns=True, transposed=True),
    ),
    "assembly-gradient-0-columns": (
        "node 0's column of the gradient operator dF/dx (the B matrix) written as minus the "
        "sums over the other axis of M^-1 (its row sums, e.g. -Dm_inv.sum(axis=2) for "
        "-Dm_inv.sum(axis=1)), the partition of unity D_0 = -(D_1 + D_2 + D_3) broken, while "
        "F = Ds M^-1 is right",
        _assembly_only(node_zero_from_columns=True, transposed=False),
    ),
    "F-identity-plus-positions": (
        "the deformation gradient written F = I + grad x, the gradient of the current positions "
        "where that of the displacements u = x - X belongs (F = I + grad u): every cell's F is "
        "the right one plus I",
        _identity_plus_positions,
    ),
}

#: Round-off allowed per cell of a prediction at F', in units of kappa(F')^2 (a hundred double
#: unit round-offs): an engine and the oracle computing at the same ill-conditioned F' agree
#: no better than that.
ROUNDOFF = 100 * np.finfo(np.float64).eps

#: A prediction whose round-off floor exceeds this share of its own size tells nothing (cells
#: F' nearly flattens, or an energy that overflows there): the hypothesis is not tried.
UNTESTABLE = 1e-4


@dataclass(frozen=True)
class GradientOutput:
    """An engine's force f (n, 3) and stiffness K with the slipped gradients, the round-off
    floors of each (norms: :data:`ROUNDOFF` kappa(F')^2 times each cell's element vector or
    matrix) and the largest kappa(F').
    """

    f: np.ndarray
    K: sp.csr_matrix
    floor_f: float
    floor_K: float
    kappa: float


def gradient_output(
    model: Any, points: np.ndarray, split: ElementSplit, x: np.ndarray, gradients: Gradients
) -> Optional[GradientOutput]:
    """The output of an engine that forms F' (sum_a x_a D'_a^T unless the slip says), its force
    -V' P(F') D'_a and matrix V' D'_a . A(F') . D'_b with (D', V', F') = gradients(split, x);
    None where the material cannot be evaluated at F' or the result is not finite.
    """
    D, V, F2 = gradients(split, x)
    if F2 is None:
        F2 = np.einsum("mak,mai->mki", x[split.cells], D)
    # F' may be inverted (det F' < 0). An engine that forms W from C = F'^T F' (J = sqrt(det
    # C)) answers there as at the reflected Q F' (Q = diag(-1, 1, 1), the same C): P = Q P(Q F')
    # and A[H] = Q A(Q F')[Q H]. One that takes J = det F' has no finite answer: no match.
    q = np.where(np.linalg.det(F2) < 0.0, -1.0, 1.0)
    Q = np.broadcast_to(np.eye(3), F2.shape).copy()
    Q[:, 0, 0] = q
    with np.errstate(all="ignore"):
        at = piola_at(model, points, split, Q @ F2)
        if at is None:
            return None
        P, A = at
        P = Q @ P
        A = np.einsum("mkp,mpilj,mlq->mkiqj", Q, A, Q)
        fe = piola_element_forces(V, D, P)
        Ke = tangent_element_matrices(V, D, A)
        if not (np.all(np.isfinite(fe)) and np.all(np.isfinite(Ke))):
            return None
        f, K = assemble(split.cells, split.n, fe, Ke)
        # What any computation at F' leaves to round-off: C = F'^T F' has the condition number
        # kappa(F')^2, and a cell F' nearly flattens can have kappa in the thousands.
        kappa = np.linalg.cond(F2)
        cond = kappa**2 * ROUNDOFF
        floor_f = float(np.linalg.norm(cond * np.linalg.norm(fe.reshape(len(fe), -1), axis=1)))
        floor_K = float(np.linalg.norm(cond * np.linalg.norm(Ke.reshape(len(Ke), -1), axis=1)))
    return GradientOutput(f, K, floor_f, floor_K, float(np.max(kappa)))


def gradient_slip_findings(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> List[Finding]:
    """The slips of :data:`GRADIENT_SLIPS` whose output matches the engine's (several:
    ambiguous); not the oracle's own output.
    """
    found = []
    f = np.asarray(f, dtype=np.float64)
    K = sp.csr_matrix(K)
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    for code, (words, gradients) in GRADIENT_SLIPS.items():
        out = gradient_output(model, points, split, positions, gradients)
        if out is None:
            continue
        g = grown(s, out.f, out.K)
        room_f, room_K = out.floor_f / g.force, out.floor_K / g.stiffness
        if not (room_f <= UNTESTABLE and room_K <= UNTESTABLE):
            continue  # round-off at that F' leaves nothing to compare
        e = errors(f, K, None, out.f, out.K, 0.0, g)
        if not (e.force <= max(tol.force, room_f) and e.stiffness <= max(tol.stiffness, room_K)):
            continue
        if tol.within(errors(out.f, out.K, None, f0, K0, 0.0, g), energy=False):
            continue  # the slip changes nothing on this state: no evidence
        found.append(
            Finding(
                code,
                words,
                FULL,
                "the material (MJED, whose sum is the oracle's to "
                f"{split.residual:.1e} on this case) at the F those gradients form, its force "
                "and matrix built with them: force error "
                f"{e.force:.1e}, stiffness error {e.stiffness:.1e} (the round-off a "
                f"computation at that F' leaves: {room_f:.1e} and {room_K:.1e}, from the "
                f"condition number of F' squared, up to {out.kappa**2:.1e})",
                {"residual": max(e.force, e.stiffness)},
            )
        )
    return ambiguous(found)


def shape_gradient_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the mistaken gradients the engine
    matches, named first; unchanged when none does or MJED does not split this case.
    """
    from dataclasses import replace

    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    found = shape_gradient_findings(
        split, ci.model, ci.points, ci.positions, out.force, out.stiffness, s, tol
    ) or gradient_slip_findings(
        split, ci.model, ci.points, ci.positions, out.force, out.stiffness, s, tol
    )
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
