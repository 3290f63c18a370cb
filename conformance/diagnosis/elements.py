"""Mistakes made inside one element, tested on the oracle's element matrices.

Some mistakes cannot be undone on the assembled output: an element matrix scattered in another
local dof order, or a force that is the divergence of another stress measure. Both live in the
cell, so they are tested by building what such an engine would assemble from per-cell
quantities and comparing it with the engine's output.

The per-cell quantities (element forces and 12 x 12 element matrices) come from the project's
MJED engine for the case's material, used only once their sum is the oracle's force and
stiffness within the case's tolerance: the oracle stays the judge, MJED only splits its answer
into cells. A user energy (no MJED material) or a split that does not add up tests nothing.

1. **Local dof order.** The element matrix written in another order of its 12 local dofs
   (component-major: x of the four nodes, then y, then z; or the four nodes in another order)
   and scattered with the node-major map ``3 * cells[e, a] + c``. Each of the 47 orders is
   assembled; one is named when it alone matches. Beside them, the element matrix computed as
   a (4, 3, 4, 3) array with its axes in another order (an einsum output 'mabik') and reshaped
   as if node-major: entries scrambled beyond a reordering of the dofs (stiffness only).
2. **Stress measure.** Per cell, the oracle's first Piola stress P and its derivative
   A = dP/dF are read back from the element force and matrix (f_a = -V0 P D_a,
   K_ab = V0 D_a . A . D_b); the engine is compared with the force and stiffness of
   P' = M(P, F) for the usual confusions (Cauchy, Kirchhoff, second Piola-Kirchhoff, P^T,
   P / J, J P), the derivative of M taken by complex step (exact to round-off).
3. **Shape-function gradients.** Built from another rest edge matrix (transposed):
   :mod:`conformance.diagnosis.shape_gradients` (its own reading, after these).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Errors, Scales, Tolerances, errors

__all__ = [
    "ElementSplit",
    "element_split",
    "mjed_element_arrays",
    "alike_cells",
    "assemble",
    "piola_element_forces",
    "tangent_element_matrices",
    "cell_kinematics",
    "cell_piola",
    "prediction_errors",
    "mirrored_pairs",
    "local_orders",
    "element_layouts",
    "order_findings",
    "STRESS_MEASURES",
    "stress_measure_findings",
    "split_finding",
    "split_reading",
    "element_reading",
]


@dataclass(frozen=True)
class ElementSplit:
    """The oracle's answer split into cells.

    cells: (m, 4); n: nodes; V0: (m,) rest volumes; D: (m, 4, 3) shape gradients;
    F: (m, 3, 3) deformation gradients; fe: (m, 4, 3) element forces; Ke: (m, 12, 12) element
    matrices, local dof 3 a + c; residual: how far their sum is from the oracle (relative).
    """

    cells: np.ndarray
    n: int
    V0: np.ndarray
    D: np.ndarray
    F: np.ndarray
    fe: np.ndarray
    Ke: np.ndarray
    residual: float
    positions: Optional[np.ndarray] = None  # (n, 3) where known


def assemble(
    cells: np.ndarray, n: int, fe: np.ndarray, Ke: Optional[np.ndarray]
) -> Tuple[np.ndarray, Optional[sp.csr_matrix]]:
    """Element forces (m, 4, 3) and matrices (m, 12, 12; None: the force alone) summed with the
    node-major map.
    """
    m = cells.shape[0]
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    f = np.zeros(3 * n)
    np.add.at(f, dof.ravel(), fe.reshape(-1))
    if Ke is None:
        return f.reshape(n, 3), None
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    K = sp.csr_matrix((Ke.reshape(-1), (rows, cols)), shape=(3 * n, 3 * n))
    return f.reshape(n, 3), K


def piola_element_forces(V0: np.ndarray, D: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Element forces (m, 4, 3) of per-cell first Piola stresses P (m, 3, 3):
    f_a,k = -V0 P_kI D_a,I, for rest volumes V0 (m,) and shape vectors D (m, 4, 3).
    """
    return -V0[:, None, None] * np.einsum("mkI,maI->mak", P, D)


def tangent_element_matrices(V0: np.ndarray, D: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Element matrices (m, 12, 12) of per-cell tangents A = dP/dF (m, 3, 3, 3, 3), A[k, I, l, L]
    = dP_kI / dF_lL: K_ak,bl = V0 D_a,I A_kIlL D_b,L (node-major rows and columns).
    """
    Ke = np.einsum("maI,mkIlL,mbL->makbl", D, A, D, optimize=True)
    return (V0[:, None, None, None, None] * Ke).reshape(-1, 12, 12)


def mirrored_pairs(Ke: np.ndarray, computed: str = "upper") -> np.ndarray:
    """Element matrices (m, 12, 12) as an engine that computes one triangle of each cell's 3x3
    node blocks and writes the other as their transposes has them: block (a, b) replaced by
    block (b, a)^T where a > b (``computed`` "upper": local pairs a <= b computed) or a < b
    ("lower"). A symmetric element matrix is unchanged.
    """
    m = Ke.shape[0]
    B = Ke.reshape(m, 4, 3, 4, 3)
    a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    written = a > b if computed == "upper" else a < b
    out = np.where(written[None, :, None, :, None], B.transpose(0, 3, 4, 1, 2), B)
    return out.reshape(m, 12, 12)


def cell_kinematics(
    points: np.ndarray, cells: np.ndarray, x: np.ndarray
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest volumes |V0| (m,), shape vectors D (m, 4, 3) and deformation gradients F (m, 3, 3)
    of P1 cells at positions ``x`` (n, 3): what the per-cell readings are written in.
    """
    from mjed.kinematics import deformation_gradient
    from mjed.mesh import shape_vectors

    V0, D = shape_vectors(points, cells)
    return np.abs(V0), D, deformation_gradient(x[cells], D)


def mjed_element_arrays(
    model: Any, points: np.ndarray, cells: np.ndarray, positions: np.ndarray
) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """MJED's element forces (m, 4, 3) and matrices (m, 12, 12) of ``model`` at ``positions``;
    None where MJED cannot (not an MJED material, or not at this state).
    """
    import mjed

    try:
        field = mjed.make_force_field(mjed.TetMesh(points, cells), model)
        fe = np.asarray(field.element_forces(positions), dtype=np.float64)
        Ke = np.asarray(field.element_stiffness(positions), dtype=np.float64)
    except Exception:  # noqa: BLE001 - not an MJED material, or not at this state: no split
        return None
    return fe, Ke


def alike_cells(F: np.ndarray) -> bool:
    """Whether every cell has one deformation gradient, F (m, 3, 3) (a homogeneous state)."""
    return bool(np.abs(F - F[:1]).max() <= 1e-9 * max(float(np.abs(F).max()), 1e-300))


def element_split(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    positions: np.ndarray,
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
) -> Optional[ElementSplit]:
    """MJED's element forces and matrices for ``model`` at ``positions``, or None when MJED has
    no such material or their sum is not the oracle's force and stiffness within ``tol``.
    """
    arrays = mjed_element_arrays(model, points, cells, positions)
    if arrays is None:
        return None
    fe, Ke = arrays
    n = points.shape[0]
    f, K = assemble(cells, n, fe, Ke)
    e = errors(f, K, None, f_o, sp.csr_matrix(K_o), 0.0, s)
    if not tol.within(e, energy=False):
        return None
    V0, D, F = cell_kinematics(points, cells, positions)
    residual = float(max(e.force, e.stiffness))
    return ElementSplit(cells, n, V0, D, F, fe, Ke, residual, np.asarray(positions, dtype=float))


#: Largest mesh (cells) the per-cell readings read: their fits hold (m, 90, 9) arrays and more.
MAX_CELLS = 5000


def case_split(diag: Any, ci: Any, ref: Any, s: Scales) -> Optional[ElementSplit]:
    """The oracle's answer at case ``ci`` split into cells for a per-cell reading; None for a
    mesh above :data:`MAX_CELLS`, or when MJED's split does not add up to the oracle's ``ref``
    within ``diag``'s tolerances.
    """
    if ci.cells.shape[0] > MAX_CELLS:
        return None
    return element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, diag.tolerances
    )


# ------------------------------------------------------------------ local dof order
def local_orders() -> List[Tuple[np.ndarray, str]]:
    """(p, words) for every local order but node-major in the given node order: the engine's
    local dof i holds the value of the node-major local dof p[i].
    """
    out = []
    for perm in itertools.permutations(range(4)):
        nodes = np.array(perm)
        node_major = (3 * nodes[:, None] + np.arange(3)).ravel()  # i = 3 a' + c
        comp_major = (3 * nodes[None, :] + np.arange(3)[:, None]).ravel()  # i = 4 c + a'
        moved = "" if perm == (0, 1, 2, 3) else f" with the cell's nodes taken as {perm}"
        if moved:
            out.append((node_major, f"local nodes permuted{moved}"))
        out.append(
            (
                comp_major,
                "element matrix in local component-major order (x of the four nodes, then y, "
                f"then z){moved}, scattered with the node-major map 3*node + c",
            )
        )
    return out


#: Axes of an element matrix as a (4, 3, 4, 3) array: node a, component i, node b, component k.
_AXES = "aibk"

#: Layouts said elsewhere: node-major (right), component-major (a local order above) and the
#: 3x3 blocks transposed (:mod:`conformance.diagnosis.transposed_blocks`), and their transposes.
_LAYOUTS_ELSEWHERE = ("aibk", "iakb", "akbi", "biak", "bkai", "kbia")


def element_layouts() -> List[Tuple[Tuple[int, ...], str]]:
    """(axes, words) for every order of the element matrix's (a, i, b, k) axes that an engine
    may compute (an einsum's output, e.g. 'mabik') and then reshape to (12, 12) as if it were
    node-major 'maibk': the entries scrambled beyond a reordering of the local dofs. axes: the
    engine's array is the right one's ``transpose(axes)``.
    """
    out = []
    for perm in itertools.permutations(range(4)):
        name = "".join(_AXES[p] for p in perm)
        # Its transpose (a <-> b, i <-> k) lays a symmetric element matrix out the same way:
        # one of the pair is tested, and the words say both.
        twin = name.translate(str.maketrans("abik", "bak" + "i"))
        if name in _LAYOUTS_ELSEWHERE or twin < name:
            continue
        words = (
            f"element stiffness computed with its indices in the order ({', '.join(name)}) "
            f"(an einsum output 'm{name}', or 'm{twin}', the same for a symmetric element "
            "matrix) and reshaped to (12, 12) as if it were (a, i, b, k) "
            "('maibk', node-major; a, b nodes, i, k components): the entries of every element "
            "matrix scrambled before the node-major scatter"
        )
        out.append((perm, words))
    return out


def split_finding(code: str, title: str, split: ElementSplit, how: str, e, figures) -> Finding:
    """A finding that the oracle's element matrices, ``how`` changed ("reordered", "laid out")
    and assembled, match the engine with errors ``e``.
    """
    return Finding(
        code,
        title,
        FULL,
        "the oracle's element matrices (MJED's, whose sum is the oracle's to "
        f"{split.residual:.1e}) {how} so and assembled: force error {e.force:.1e}, "
        f"stiffness error {e.stiffness:.1e}",
        figures,
    )


def _layout_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The layouts of :func:`element_layouts` whose element matrices, assembled with the force
    right, match the engine and differ from the oracle's.
    """
    m = split.cells.shape[0]
    Ke4 = split.Ke.reshape(m, 4, 3, 4, 3)
    return _matrix_slip_findings(
        split,
        f,
        K,
        s,
        tol,
        (
            (
                "element-layout",
                f"element matrix in another layout (stiffness only): {words}",
                "laid out",
                {"layout": "".join(_AXES[p] for p in perm)},
                Ke4.transpose(0, *(1 + np.array(perm))).reshape(m, 12, 12),
            )
            for perm, words in element_layouts()
        ),
    )


def _matrix_slip_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances, slips
) -> List[Finding]:
    """The slips whose element matrices, assembled with the force right, match the engine and
    differ from the oracle's. slips: (code, title, how they were changed, figures, element
    matrices (m, 12, 12) the engine holds instead), each computed when it is reached.
    """
    found = []
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    for code, title, how, figures, Ke in slips:
        _, K_c = assemble(split.cells, split.n, split.fe, Ke)
        if tol.within(errors(f0, K_c, None, f0, K0, 0.0, s), energy=False):
            continue  # the oracle's own matrix here: no evidence either way
        e = errors(f, sp.csr_matrix(K), None, f0, K_c, 0.0, s)
        if tol.within(e, energy=False):
            found.append(split_finding(code, title, split, how, e, figures))
    return found


def _mirrored(pairs: np.ndarray, at: Tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(m, 78) values put at the triangle positions ``at`` (in that order) and mirrored."""
    K = np.zeros((pairs.shape[0], 12, 12))
    K[:, at[0], at[1]] = pairs
    return K + np.swapaxes(K, 1, 2) - K * np.eye(12)


def storage_slips() -> List[Tuple[str, Callable[[np.ndarray], np.ndarray]]]:
    """(words, element matrices (m, 12, 12) -> what the engine stores instead): the element
    matrix's values moved by a slip of how they are packed or buffered, not by a layout of its
    axes: the 78 values of the upper triangle (row by row) unpacked into the lower triangle's
    positions, and a buffer of one row per entry or pair, (k, m), read back with reshape(m, k)
    for its transpose (each cell then holds values of other cells).
    """
    up = np.triu_indices(12)

    def packed_upper_as_lower(Ke):
        return _mirrored(Ke[:, up[0], up[1]], np.tril_indices(12))

    def pair_buffer_reshaped(Ke):
        pairs = Ke[:, up[0], up[1]]  # (m, 78), unpacked again in the same (upper) order
        return _mirrored(pairs.T.copy().reshape(pairs.shape), up)

    def entry_buffer_reshaped(Ke):
        m = Ke.shape[0]
        return Ke.reshape(m, 144).T.copy().reshape(m, 12, 12)

    # dof map 3 np.repeat(cells, 3, axis=1) + np.repeat(np.arange(3), 4): local column q goes
    # to node q // 3, component q // 4 (several columns onto one dof, some dofs never
    # reached), so the engine adds P^T Ke P with P[q, 3 (q // 3) + q // 4] = 1
    q = np.arange(12)
    gather = np.zeros((12, 12))
    gather[q, 3 * (q // 3) + q // 4] = 1.0

    def dof_map_repeated(Ke):
        return np.einsum("qd,mqr,re->mde", gather, Ke, gather)

    return [
        (
            "the 78 values of each symmetric element matrix taken from its upper triangle row "
            "by row and unpacked into the lower triangle's positions (triu order read as tril "
            "order), then mirrored",
            packed_upper_as_lower,
        ),
        (
            "the element matrices' 78 pair values buffered one row per pair, (78, m), and read "
            "back with reshape(m, 78) where the transpose belongs: every cell's matrix filled "
            "with values of other cells and pairs",
            pair_buffer_reshaped,
        ),
        (
            "the element matrices buffered one row per entry, (144, m), and read back with "
            "reshape(m, 12, 12) where the transpose belongs: every cell's matrix filled with "
            "values of other cells",
            entry_buffer_reshaped,
        ),
        (
            "the cell-to-dof map built with np.repeat(np.arange(3), 4) where np.tile(np.arange(3), "
            "4) belongs (3 np.repeat(cells, 3, axis=1) + ...): the local components run "
            "0, 0, 0, 0, 1, ... against the nodes, so the element matrices are scattered to "
            "wrong and repeated dofs",
            dof_map_repeated,
        ),
    ]


def _storage_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The storage slips of :func:`storage_slips` whose element matrices, assembled with the
    force right, match the engine (and differ from the oracle's).
    """
    return _matrix_slip_findings(
        split,
        f,
        K,
        s,
        tol,
        (
            (
                "element-storage",
                f"element matrix values stored wrongly (stiffness only): {words}",
                "stored",
                {},
                slip(split.Ke),
            )
            for words, slip in storage_slips()
        ),
    )


def _perturbation_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """Slips of an element stiffness built column by column from perturbed element forces
    (differences or a complex step), the force right: the perturbation not reset between the
    dofs (column j the sum of columns 0..j), or a relative step x_j (1 + h) divided by h alone
    (column j times the coordinate x_j it perturbs).
    """
    candidates = [
        (
            "element-columns-accumulated",
            "element stiffness columns accumulated: column j is the sum of the true columns "
            "0..j (a difference or complex-step perturbation not reset between the element's "
            "dofs)",
            split.Ke @ np.triu(np.ones((12, 12))),
        )
    ]
    if split.positions is not None:
        xe = split.positions[split.cells].reshape(-1, 1, 12)
        candidates.append(
            (
                "element-columns-coordinates",
                "element stiffness column j times the coordinate x_j it perturbs: a relative "
                "step, x_j (1 + h) or x_j (1 + i h) for a complex step, divided by h where h x_j "
                "belongs",
                split.Ke * xe,
            )
        )
    f_right = assemble(split.cells, split.n, split.fe, None)[0]
    found = []
    for code, words, Ke in candidates:
        _, Kc = assemble(split.cells, split.n, split.fe, Ke)
        e = errors(f, sp.csr_matrix(K), None, f_right, Kc, 0.0, s)
        if tol.within(e, energy=False):
            found.append(split_finding(code, words, split, "changed", e, {"element": code}))
    return found


#: Per-cell node orders an engine may build its dof map from (a sorted copy of the cells,
#: made for a sparsity pattern or a hash of the cell, reused for the scatter): name -> rows.
SORTED_MAPS = {
    "sorted": lambda cells: np.sort(cells, axis=1),
    "sorted in decreasing order": lambda cells: -np.sort(-cells, axis=1),
}


def _sorted_map_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """Element results in the cell's given node order scattered through its node ids sorted
    (each cell's own permutation, not one local order for all), that match the engine's force
    and stiffness; none when no cell's nodes are out of that order.
    """
    found = []
    for name, order in SORTED_MAPS.items():
        rows = order(split.cells)
        moved = int(np.sum(np.any(rows != split.cells, axis=1)))
        if moved == 0:
            continue
        f_p, K_p = assemble(rows, split.n, split.fe, split.Ke)
        e = errors(f, sp.csr_matrix(K), None, f_p, K_p, 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                split_finding(
                    "element-order",
                    f"element dof map built from each cell's node ids {name} (a sorted copy of "
                    "the cells, e.g. made for the sparsity pattern) while the element's "
                    "coordinates, forces and matrix follow the kit's node order: in the "
                    f"{moved} cells whose nodes are listed otherwise, forces and blocks go to "
                    "the wrong nodes",
                    split,
                    "scattered",
                    e,
                    {"order": name, "which": "force and stiffness", "cells": moved},
                )
            )
    return found


def order_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The local orders whose assembly matches the engine (force in that order too, or the
    force right and only the matrix reordered), and the element layouts
    (:func:`element_layouts`); several are said as ambiguous.
    """
    found = _layout_findings(split, f, K, s, tol) + _perturbation_findings(split, f, K, s, tol)
    found += _sorted_map_findings(split, f, K, s, tol) + _storage_findings(split, f, K, s, tol)
    f_right = assemble(split.cells, split.n, split.fe, None)[0]
    # the columns alone in component-major order are the layout (a, i, k, b), said above
    said = (3 * np.arange(4)[None, :] + np.arange(3)[:, None]).ravel()
    for p, words in local_orders():
        fp = split.fe.reshape(-1, 12)[:, p].reshape(-1, 4, 3)
        f_both, K_p = assemble(split.cells, split.n, fp, split.Ke[:, p][:, :, p])
        # A stiffness of differences or of a complex step takes its rows from the engine's
        # element force (reordered with it) and its columns from the dofs it perturbs.
        K_rows = assemble(split.cells, split.n, fp, split.Ke[:, p, :])[1]
        K_cols = assemble(split.cells, split.n, split.fe, split.Ke[:, :, p])[1]
        for fo, K_pred, which in (
            (f_both, K_p, "force and stiffness"),
            (f_right, K_p, "stiffness only"),
            (f_both, K_rows, "the force and the stiffness's rows, its columns right"),
            (f_right, K_cols, "the stiffness's columns only: the dofs perturbed in that order"),
        ):
            if K_pred is K_cols and np.array_equal(p, said):
                continue
            e = errors(f, sp.csr_matrix(K), None, fo, K_pred, 0.0, s)
            if tol.within(e, energy=False):
                found.append(
                    split_finding(
                        "element-order",
                        f"element dofs in another local order ({which}): {words}",
                        split,
                        "reordered",
                        e,
                        {"order": [int(i) for i in p], "which": which},
                    )
                )
                break
    return ambiguous(found)


# ------------------------------------------------------------------ stress measures
def _inv(A):
    return np.linalg.inv(A)


def _det(A):
    return np.linalg.det(A)


def _t(A):
    return np.swapaxes(A, -1, -2)


#: code -> (the stress used as P, in words; M(P, F): the engine's P'), each analytic in P and F.
STRESS_MEASURES: dict = {
    "cauchy": (
        "the Cauchy stress sigma = P F^T / J",
        lambda P, F: P @ _t(F) / _det(F)[:, None, None],
    ),
    "kirchhoff": ("the Kirchhoff stress tau = P F^T", lambda P, F: P @ _t(F)),
    "second-piola": ("the second Piola-Kirchhoff stress S = F^-1 P", lambda P, F: _inv(F) @ P),
    "piola-transposed": ("P^T = S F^T (F S and S F^T confused)", lambda P, F: _t(P)),
    "cauchy-rest-volume": (
        "sigma F^-T = P / J: the Cauchy stress integrated over the rest volume (the J of "
        "P = J sigma F^-T missing)",
        lambda P, F: P / _det(F)[:, None, None],
    ),
    "pushforward-transposed": (
        "the Cauchy stress pushed forward with F transposed, F^T S F / J where F S F^T / J "
        "belongs (the same where F is symmetric): J F^T S F F^-T / J",
        lambda P, F: _t(F) @ _inv(F) @ P @ F @ _inv(_t(F)),
    ),
    "kirchhoff-as-second-piola": (
        "F tau (the Kirchhoff stress tau = P F^T taken for S in P = F S)",
        lambda P, F: F @ P @ _t(F),
    ),
    "cauchy-as-second-piola": (
        "F sigma (the Cauchy stress sigma = P F^T / J taken for S in P = F S)",
        lambda P, F: F @ P @ _t(F) / _det(F)[:, None, None],
    ),
    "deformed-volume": (
        "J P = tau F^-T, a factor J in each cell: the first Piola stress integrated over the "
        "deformed volume, the Kirchhoff stress tau used as the Cauchy stress, or the spatial "
        "gradients taken from cof F = J F^-T (the 1/J of F^-T dropped)",
        lambda P, F: P * _det(F)[:, None, None],
    ),
}


def cell_piola(split: ElementSplit) -> Tuple[np.ndarray, np.ndarray]:
    """Per cell P (m, 3, 3) and A = dP/dF (m, 3, 3, 3, 3), A[k, i, l, j] = dP_ki / dF_lj, read
    back from the element force and matrix through the pseudo-inverse of D (rank 3): the
    oracle's stress and tangent per cell, which the other per-cell readings start from.
    """
    Dp = np.linalg.pinv(split.D)  # (m, 3, 4): Dp D = I
    V = split.V0
    P = -np.einsum("mja,mak->mkj", Dp, split.fe) / V[:, None, None]
    Ke = split.Ke.reshape(-1, 4, 3, 4, 3)
    A = np.einsum("mia,makbl,mjb->mkilj", Dp, Ke, Dp) / V[:, None, None, None, None]
    return P, A


def prediction_errors(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    prediction: Tuple[np.ndarray, sp.spmatrix],
    s: Scales,
    tol: Tolerances,
) -> Optional[Errors]:
    """The engine's errors (force f (n, 3), stiffness K) against a mistake's ``prediction``
    (force, stiffness), or None unless they are within ``tol``, the prediction is finite and it
    is not the oracle's own (the split's sum) within ``tol`` (then it is no evidence).
    """
    fv, Kv = prediction[0], sp.csr_matrix(prediction[1])
    if not (np.all(np.isfinite(fv)) and np.all(np.isfinite(Kv.data))):
        return None
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    if tol.within(errors(fv, Kv, None, f0, K0, 0.0, s), energy=False):
        return None
    e = errors(f, sp.csr_matrix(K), None, fv, Kv, 0.0, s)
    return e if tol.within(e, energy=False) else None


def _measure_output(
    split: ElementSplit, P: np.ndarray, A: np.ndarray, M: Callable
) -> Tuple[np.ndarray, sp.csr_matrix]:
    """Force and stiffness of an engine whose first Piola stress is M(P, F)."""
    h = 1e-30
    Pm = np.real(M(P.astype(complex), split.F.astype(complex)))
    dPm = np.empty_like(A)
    for ll in range(3):
        for j in range(3):
            H = np.zeros((3, 3))
            H[ll, j] = 1.0
            Pc = P + 1j * h * A[:, :, :, ll, j]
            Fc = split.F + 1j * h * H
            dPm[:, :, :, ll, j] = np.imag(M(Pc, Fc)) / h
    fe = piola_element_forces(split.V0, split.D, Pm)
    return assemble(split.cells, split.n, fe, tangent_element_matrices(split.V0, split.D, dPm))


def stress_measure_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The stress measures whose force and stiffness match the engine's (several: ambiguous).

    A measure whose force is the oracle's on this state (P^T where P is symmetric, as on a
    uniaxial stretch with F and S diagonal) is not named: the force, which the finding is
    about, cannot show it there, and what is left is a stiffness that other tangent slips
    predict alike (Teran's 2x2 SVD blocks with their entries exchanged, for P^T).
    """
    P, A = cell_piola(split)
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    found = []
    for code, (words, M) in STRESS_MEASURES.items():
        with np.errstate(all="ignore"):
            fm, Km = _measure_output(split, P, A, M)
        if not (np.all(np.isfinite(fm)) and np.all(np.isfinite(Km.data))):
            continue
        if errors(fm, K0, None, f0, K0, 0.0, s).force <= tol.force:
            continue  # the same force as the oracle's here: no evidence of another measure
        e = errors(f, sp.csr_matrix(K), None, fm, Km, 0.0, s)
        alone = errors(f, sp.csr_matrix(K), None, fm, K0, 0.0, s)
        if not tol.within(e, energy=False) and tol.within(alone, energy=False):
            # the force alone built on it, the stiffness derived separately and right
            found.append(
                Finding(
                    f"stress-measure-{code}",
                    f"your force alone is the divergence of another stress measure: {words} "
                    "used as the first Piola stress P; your stiffness is the oracle's (derived "
                    "separately, not from that force)",
                    FULL,
                    "the oracle's P per cell (from MJED's element forces, whose sum is the "
                    f"oracle's to {split.residual:.1e}) mapped so and assembled: force error "
                    f"{alone.force:.1e}, and the oracle's own stiffness: error "
                    f"{alone.stiffness:.1e}",
                    {
                        "measure": code,
                        "force_only": True,
                        "residual": max(alone.force, alone.stiffness),
                    },
                )
            )
        elif tol.within(e, energy=False):
            found.append(
                Finding(
                    f"stress-measure-{code}",
                    f"your force is the divergence of another stress measure: {words} used as "
                    "the first Piola stress P",
                    FULL,
                    "the oracle's P and dP/dF per cell (from MJED's element matrices, whose sum "
                    f"is the oracle's to {split.residual:.1e}) mapped so, differentiated by "
                    f"complex step and assembled: force error {e.force:.1e}, stiffness error "
                    f"{e.stiffness:.1e}",
                    {"measure": code, "residual": max(e.force, e.stiffness)},
                )
            )
    return ambiguous(found)


def split_reading(diag, ci, out, ref, s: Scales, finders: Sequence[Callable[..., list]]):
    """``diag`` (a failed case nothing explained yet) with the findings of the first of
    ``finders`` (each (split, f, K, s, tol) -> findings) that finds any on the oracle's element
    split, named first (the 'unexplained' finding dropped); unchanged when none matches or the
    split does not add up to the oracle.
    """
    from dataclasses import replace

    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    for finder in finders:
        found = finder(split, out.force, out.stiffness, s, tol)
        if found:
            rest = [f for f in diag.findings if f.code != "unexplained"]
            return replace(diag, findings=[*found, *rest])
    return diag


def element_reading(diag, ci, out, ref, s: Scales, *more_finders):
    """``diag`` with the element mistakes the engine matches (:func:`split_reading`): a local
    dof order, a stress measure, then ``more_finders`` (the run passes each cell's force or
    stiffness times its J, the volume confused: :mod:`conformance.diagnosis.volumes`, which
    builds on this module and so is handed in rather than imported here).
    """
    return split_reading(
        diag, ci, out, ref, s, (order_findings, stress_measure_findings, *more_finders)
    )
