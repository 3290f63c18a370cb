"""Fibre-frame mistakes as oracle variants: what the oracle gives with the frame an engine
probably used instead of the one in the kit.

A frame mistake cannot be undone on the engine's output the way a sign or a dof order can: the
error lives inside the energy. So the hypothesis is tested the other way round: the oracle is
evaluated with the mistaken frame, and the mistake is named when the engine agrees with that
variant within the tolerance. The mistakes (docs/conventions.md, "The diagnosis"):

- ``frame-ignored``: the identity frame (fibre, sheet and normal taken as the global x, y, z, as
  an engine that never reads frame.f64 does);
- ``frame-transposed``: each cell's R^T for R (rows read as the fibre, sheet and normal, or the
  global-to-material rotation used as material-to-global; also what a column-major reader
  of the row-major file gets);
- ``frame-global``: one frame for the whole mesh, the first cell's (the material axes held
  fixed in space instead of following the field: an engine that reads frame.f64 as one
  (3, 3) rotation);
- ``frame-twice``: the frame applied twice, R R for R (a helper rotating the strain into the
  frame that its caller had already rotated), or R^T R^T;
- ``frame-shifted``: per-cell frames read one cell off (cell i given cell i - 1's or i + 1's
  frame: an off-by-one index, or frames written in another cell order), the end wrapping
  round or held;
- ``frame-cells-sorted``: the cells reordered by a sort key (their lowest node, their first node,
  their sorted node numbers, a coordinate of their rest centroid; a stable sort) for the
  engine's own loop or scatter, the per-cell frames left in the kit's cell order: the engine's
  j-th cell, the kit's cell order[j], given the kit's frame j;
- ``frame-node-indexed``: per-cell frames looked up by a node number, cell k given
  frame[cells[k, a]] (an engine that stores the frames per node, or indexes them with the
  connectivity), one variant per local node a, where every node number is a cell index;
- ``frame-smoothed``: per-cell frames smoothed through the nodes (each node the mean of its
  cells' frames, each cell the mean of its nodes', made rotations again by the polar factor or
  Gram-Schmidt, at the nodes too or only in the cells), as an engine storing the field per node;
- ``frame-averaged``: one frame for the whole mesh, the mean of the cells' frames made a
  rotation again (by Gram-Schmidt from the mean fibre, or as the nearest rotation);
- ``frame-layout``: the kit's row-major (m, 3, 3) frame file read in another memory layout,
  the cell index last (MATLAB's R(:, :, k): reshaped (3, 3, m)) or the whole array in column
  major (Fortran's order); the matrices so read are not rotations, and the oracle is given them
  as read (:class:`reference_fem.validation.AsReadFrame`; declared materials only);
- ``frame-rebuilt``: only the fibre read, the sheet and normal rebuilt from a global axis a
  (s = a x f / |a x f|, n = f x s), one variant per axis;
- ``frame-blocked``: one frame per block of 5 or 6 cells (a hexahedron's tetrahedra), the
  block's first cell's;
- ``frame-single-precision``: the frames rounded to float32 and used in double (as read);
- ``frame-columns``: the columns taken in another order (e.g. the sheet used as the fibre), one
  hypothesis per order of the three columns; for an energy weighted by coefficients b_xy of the
  frame's strain components (Costa) this is the same energy as those coefficients exchanged,
  which the title says (the two cannot be told apart).

Two mistakes that predict the same force and stiffness cannot be told apart (for an energy of
I4 and I5, which sees only the fibre column, two column orders with the same first column):
only the first of them is kept.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import Any, Dict, List, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from common.tolerances import mean_edge_length
from conformance.judge.compare import Scales, scales
from conformance.kit.spec import CaseInput
from mjed.materials.base import Material
from reference_fem.validation import AsReadFrame

__all__ = ["FrameVariant", "frame_models", "frame_variants"]

_COLUMNS = ("fibre", "sheet", "normal")

#: Two variants whose force and stiffness differ by less than this (relative) are the same
#: prediction: round-off of one oracle, far below any frame mistake (1e-3 or more).
_SAME_PREDICTION = 1e-12


@dataclass(frozen=True)
class FrameVariant:
    """The oracle with a mistaken frame, at the case's positions.

    code, title: the mistake; force (n, 3) [N], stiffness CSR (3n, 3n) [N/m]: the variant
    oracle's values; scales: its error denominators (:func:`conformance.judge.compare.scales`).
    """

    code: str
    title: str
    force: np.ndarray
    stiffness: sp.csr_matrix
    scales: Scales


def _frame_of(model: Any) -> "np.ndarray | None":
    """The model's frame (3, 3) or (m, 3, 3), or None (no frame, or a model without one)."""
    frame = getattr(model, "frame", None)
    return None if frame is None else np.asarray(frame, dtype=np.float64)


def frame_models(
    model: Any, cells: "np.ndarray | None" = None, points: "np.ndarray | None" = None
) -> List[Tuple[str, str, Any]]:
    """(code, title, model with the mistaken frame) for each frame mistake that differs from the
    model's own frame; empty for a model without a frame or with the identity. ``cells`` (m, 4),
    the mesh's connectivity, adds the frames looked up by node number and left in the kit's
    order after the cells were sorted; ``points`` (n, 3), the rest positions, the sorts by a
    centroid coordinate.
    """
    R = _frame_of(model)
    if R is None:
        return []
    eye = np.eye(3)
    candidates = [
        ("frame-ignored", "fibre frame ignored: global x, y, z used as fibre, sheet, normal", eye),
        (
            "frame-transposed",
            "fibre frame transposed: R^T used for R (rows read as fibre, sheet, normal)",
            np.ascontiguousarray(np.swapaxes(R, -1, -2)),
        ),
        (
            "frame-global",
            "one frame for the whole mesh (the first cell's), not each cell's frame",
            R[0] if R.ndim == 3 else R,
        ),
        (
            "frame-twice",
            "fibre frame applied twice: the strain rotated into the frame a second time, "
            "R^T (R^T E R) R (R R used for R: a helper rotating what its caller had rotated)",
            np.ascontiguousarray(R @ R),
        ),
        (
            "frame-twice",
            "fibre frame applied twice the other way: R (R E R^T) R^T (R^T R^T used for R)",
            np.ascontiguousarray(np.swapaxes(R @ R, -1, -2)),
        ),
    ]
    if R.ndim == 3 and R.shape[0] > 1:
        candidates += _shifted(R)
        candidates += _averaged(R)
        if cells is not None:
            candidates += _node_indexed(R, np.asarray(cells))
            candidates += _cells_sorted(R, np.asarray(cells), points)
            candidates += _smoothed(R, np.asarray(cells))
        candidates += _blocked(R)
        if isinstance(model, Material):
            # a declared material's frame goes to the oracle as it is; a user energy's is
            # re-read (and checked again) where its formula is compiled, in another process
            candidates += _misread_layouts(R)
            candidates += _single_precision(R)
    candidates += _rebuilt_from_fibre(R)
    for order in itertools.permutations(range(3)):
        if order != (0, 1, 2):
            used = ", ".join(_COLUMNS[k] for k in order)
            title = (
                f"frame columns in another order: the {used} columns used as fibre, sheet, normal"
            )
            title += _same_as_coefficients_exchanged(model, order)
            candidates.append(("frame-columns", title, np.ascontiguousarray(R[..., list(order)])))
    out = []
    for code, title, variant in candidates:
        if np.array_equal(np.broadcast_to(variant, R.shape), R):
            continue  # the same frame as the model's: no mistake to tell apart
        try:
            if isinstance(variant, AsReadFrame):
                out.append((code, title, _with_frame_as_read(model, variant)))
            else:
                out.append((code, title, dataclasses.replace(model, frame=variant)))
        except ValueError:  # not a rotation (cells' frames mixed): the oracle cannot take it
            continue
    return out


def _with_frame_as_read(model: Any, frame: "AsReadFrame") -> Any:
    """``model`` carrying ``frame`` as read, past the material's own check that a frame is a
    rotation (the frame is what the engine computed with, not an input to validate).
    """
    variant = dataclasses.replace(model, frame=None)
    object.__setattr__(variant, "frame", frame)
    return variant


def _misread_layouts(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """The row-major frame file of R (m, 3, 3) read in two other layouts: cell index last
    (reshaped (3, 3, m), then cell k = [:, :, k]) and the whole array in column-major order;
    as :class:`AsReadFrame` (not rotations).
    """
    flat = np.ascontiguousarray(R).ravel()
    m = R.shape[0]
    layouts = (
        ("the cell index last (reshaped (3, 3, m), cell k's frame = [:, :, k], MATLAB's "
         "R(:, :, k))", flat.reshape(3, 3, m).transpose(2, 0, 1)),
        ("the whole (m, 3, 3) array in column-major (Fortran) order",
         flat.reshape((m, 3, 3), order="F")),
    )  # fmt: skip
    return [
        (
            "frame-layout",
            f"frame file read in another memory layout: {how}; the matrices so read are not "
            "rotations",
            np.ascontiguousarray(read).view(AsReadFrame),
        )
        for how, read in layouts
    ]


def _blocked(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Per-cell frames R (m, 3, 3) indexed as one frame per block of b cells, the block's first
    (cell k given frame b (k // b)): a structured mesh's hexahedra split into 5 or 6
    tetrahedra, the frames read as one per hexahedron.
    """
    m = R.shape[0]
    k = np.arange(m)
    return [
        (
            "frame-blocked",
            f"frames indexed one per block of {b} cells (a hexahedron of {b} tetrahedra): cell k "
            f"given frame {b} (k // {b}), its block's first, not its own",
            np.ascontiguousarray(R[b * (k // b)]),
        )
        for b in (5, 6)
        if m > b
    ]


def _single_precision(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Frames R rounded to float32 (stored in single precision, used in double): no longer
    orthonormal to 1e-8, so :class:`AsReadFrame`.
    """
    rounded = R.astype(np.float32).astype(np.float64)
    if np.array_equal(rounded, R):
        return []
    return [
        (
            "frame-single-precision",
            "fibre frames rounded to single precision (float32 storage) and used in double: "
            "the frames' own round-off, about 1e-7",
            np.ascontiguousarray(rounded).view(AsReadFrame),
        )
    ]


def _rebuilt_from_fibre(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Frames R ((m,) 3, 3) with only the fibre kept and the sheet and normal rebuilt from a
    global axis a: s = a x f / |a x f|, n = f x s (one variant per axis; none where a fibre is
    parallel to a, where the rebuilt frame is undefined).
    """
    f = R[..., :, 0]
    out = []
    for k, axis in enumerate("xyz"):
        s = np.cross(np.eye(3)[k], f)
        norm = np.linalg.norm(s, axis=-1, keepdims=True)
        if np.any(norm < 1e-8):
            continue
        s = s / norm
        rebuilt = np.stack([f, s, np.cross(f, s)], axis=-1)
        out.append(
            (
                "frame-rebuilt",
                f"only the fibre read from the frame: the sheet and normal rebuilt from the "
                f"global {axis} axis (s = {axis} x f / |{axis} x f|, n = f x s)",
                np.ascontiguousarray(rebuilt),
            )
        )
    return out


def _shifted(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Per-cell frames R (m, 3, 3) read one cell off: cell i given cell i - 1's or i + 1's
    frame, the end wrapping round (Python's R[i - 1]; a modulo) or held (an index clamped).
    """
    m = R.shape[0]
    i = np.arange(m)
    out = []
    for d, which in ((-1, "previous"), (1, "next")):
        for idx, end in ((np.mod(i + d, m), "wrapping round"), (np.clip(i + d, 0, m - 1), "held")):
            out.append(
                (
                    "frame-shifted",
                    f"per-cell frames shifted by one cell: cell i given the {which} cell's frame "
                    f"(i {d:+d}; the end {end})",
                    np.ascontiguousarray(R[idx]),
                )
            )
    return out


def _node_indexed(R: np.ndarray, cells: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Per-cell frames R (m, 3, 3) looked up by node number: cell k given frame[cells[k, a]],
    one variant per local node a; none where a node number is not a cell index (an engine
    doing so would have failed to run).
    """
    if cells.ndim != 2 or cells.shape[0] != R.shape[0] or cells.max() >= R.shape[0]:
        return []
    return [
        (
            "frame-node-indexed",
            f"per-cell frames indexed by a node number: cell k given frame[cells[k, {a}]] (the "
            f"number of its local node {a} used as a cell index), not its own frame",
            np.ascontiguousarray(R[cells[:, a]]),
        )
        for a in range(cells.shape[1])
    ]


def _sort_keys(cells: np.ndarray, points: "np.ndarray | None") -> List[Tuple[str, np.ndarray]]:
    """(words, order) for the sorts of the cells (m, 4) an engine may apply: a stable argsort
    by their lowest node, by their first node, lexicographic by their sorted node numbers, and
    (with the rest ``points`` (n, 3)) by each coordinate of their centroid.
    """
    s = np.sort(cells, axis=1)
    keys = [
        ("their lowest node", np.argsort(cells.min(axis=1), kind="stable")),
        ("their first node", np.argsort(cells[:, 0], kind="stable")),
        ("their sorted node numbers (lexicographically)", np.lexsort(s.T[::-1])),
    ]
    if points is not None and points.shape[0] > cells.max():
        centroid = np.asarray(points, dtype=np.float64)[cells].mean(axis=1)
        keys += [
            (
                f"the {axis} coordinate of their rest centroid",
                np.argsort(centroid[:, k], kind="stable"),
            )
            for k, axis in enumerate("xyz")
        ]
    return keys


def _cells_sorted(
    R: np.ndarray, cells: np.ndarray, points: "np.ndarray | None"
) -> List[Tuple[str, str, np.ndarray]]:
    """Per-cell frames R (m, 3, 3) left in the kit's cell order while the cells were sorted
    (:func:`_sort_keys`): the kit's cell order[j] given frame j. Sorts that leave the cells in
    place, or repeat an earlier sort's order, are left out.
    """
    if cells.ndim != 2 or cells.shape[0] != R.shape[0]:
        return []
    out, seen = [], []
    for words, order in _sort_keys(cells, points):
        moved = int(np.count_nonzero(order != np.arange(order.size)))
        if moved == 0 or any(np.array_equal(order, o) for o in seen):
            continue
        seen.append(order)
        used = np.empty_like(R)
        used[order] = R
        out.append(
            (
                "frame-cells-sorted",
                f"fibre frames assigned to the wrong cells: the cells reordered by {words} "
                "(a stable sort, e.g. for the scatter's locality) but the per-cell frames left "
                f"in the kit's cell order, so {moved} of the {order.size} cells get another "
                "cell's frame (a permutation of the frames)",
                np.ascontiguousarray(used),
            )
        )
    return out


def _rotations(M: np.ndarray, how: str) -> np.ndarray:
    """(k, 3, 3) matrices made rotations again: "polar" the nearest rotation (SVD), "gram" by
    Gram-Schmidt from the first column (the fibre kept in direction, the sheet made orthogonal
    to it, the normal their cross product).
    """
    if how == "polar":
        U, _, Vt = np.linalg.svd(M)
        Q = U @ Vt
        # a reflection's nearest proper rotation: the last singular direction flipped
        flip = np.linalg.det(Q) < 0
        U[flip, :, -1] *= -1.0
        return U @ Vt
    f = M[:, :, 0] / np.linalg.norm(M[:, :, 0], axis=1, keepdims=True)
    b = M[:, :, 1] - f * np.einsum("ki,ki->k", f, M[:, :, 1])[:, None]
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    return np.stack([f, b, np.cross(f, b)], axis=-1)


def _smoothed(R: np.ndarray, cells: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """Per-cell frames R (m, 3, 3) smoothed through the nodes (a field stored per node, or
    interpolated for a plot and read back): each node given the mean of its cells' frames, each
    cell the mean of its nodes' (m, 4 of them), made a rotation again by the polar factor or
    Gram-Schmidt, at the nodes too or only in the cells. None where a mean vanishes.
    """
    if cells.ndim != 2 or cells.shape[0] != R.shape[0]:
        return []
    n = int(cells.max()) + 1
    total = np.zeros((n, 3, 3))
    np.add.at(total, cells.ravel(), np.repeat(R, cells.shape[1], axis=0))
    count = np.bincount(cells.ravel(), minlength=n).astype(float)
    nodes = total / np.maximum(count, 1.0)[:, None, None]
    out = []
    for how, words in (("polar", "the nearest rotation"), ("gram", "Gram-Schmidt")):
        for at_nodes in (False, True):
            node_frames = _rotations(nodes, how) if at_nodes else nodes
            mean = node_frames[cells].mean(axis=1)
            if np.min(np.linalg.norm(mean[:, :, :2], axis=1)) < 1e-8:
                continue
            where = "at the nodes and in the cells" if at_nodes else "in the cells"
            out.append(
                (
                    "frame-smoothed",
                    "fibre frames smoothed through the nodes: each node given the mean of its "
                    "cells' frames, each cell the mean of its nodes' (made rotations again by "
                    f"{words} {where}), not the cell's own frame",
                    _rotations(mean, how),
                )
            )
    return out


def _averaged(R: np.ndarray) -> List[Tuple[str, str, np.ndarray]]:
    """One frame for all cells from the mean of R (m, 3, 3), made a rotation again two ways:
    Gram-Schmidt from the mean fibre (sheet made orthogonal to it, normal their cross product)
    and the nearest rotation (polar factor of the mean, by SVD). None where the mean fibre or
    sheet vanishes.
    """
    mean = R.mean(axis=0)
    f, b = mean[:, 0], mean[:, 1]
    s = b - f * (f @ b) / max(f @ f, 1e-300)
    if np.linalg.norm(f) < 1e-8 or np.linalg.norm(s) < 1e-8:
        return []
    f, s = f / np.linalg.norm(f), s / np.linalg.norm(s)
    U, _, Vt = np.linalg.svd(mean)
    return [
        (
            "frame-averaged",
            "one frame for the whole mesh: the cells' frames averaged and re-orthonormalised "
            "(Gram-Schmidt from the mean fibre), not each cell's own frame",
            np.stack([f, s, np.cross(f, s)], axis=-1),
        ),
        (
            "frame-averaged",
            "one frame for the whole mesh: the nearest rotation to the mean of the cells' "
            "frames (polar factor), not each cell's own frame",
            U @ Vt,
        ),
    ]


_LETTERS = "fsn"  # fibre, sheet, normal: the indices of a frame energy's coefficients b_xy


def _same_as_coefficients_exchanged(model: Any, order: Tuple[int, ...]) -> str:
    """For an energy of the frame-strain components weighted by coefficients b_xy (Costa's
    B matrix), the columns taken in ``order`` give exactly the energy with the coefficients
    permuted the same way: '; the same energy as b_fs and b_fn exchanged ...', naming the
    coefficients whose values that changes (the two mistakes cannot be told apart), or ''.
    """
    value: Dict[Tuple[int, int], Tuple[str, float]] = {}
    for a in range(3):
        for b in range(3):
            for name in (f"b_{_LETTERS[a]}{_LETTERS[b]}", f"b_{_LETTERS[b]}{_LETTERS[a]}"):
                if hasattr(model, name):
                    value[a, b] = (name, float(getattr(model, name)))
                    break
            else:
                return ""
    # Column k of the frame used is column order[k] of the true one, so the term of entry
    # (a, b) reads the true component (order[a], order[b]), weighted by B[a, b], not its own.
    pairs = set()
    for a in range(3):
        for b in range(a, 3):
            name, v = value[a, b]
            true_name, true_v = value[order[a], order[b]]
            if true_v != v:
                pairs.add(tuple(sorted((name, true_name))))
    if not pairs:
        return ""
    named = [n for p in sorted(pairs) for n in p]
    if len(set(named)) < len(named):  # a cycle, not exchanges
        said = ", ".join(sorted(set(named))) + " permuted"
    else:
        said = " and ".join(f"{x} and {y} exchanged" for x, y in sorted(pairs))
    return f"; the same energy as {said} (the frame right): the two cannot be told apart"


def frame_variants(case: CaseInput, cache: Any) -> List[FrameVariant]:
    """The oracle at ``case.positions`` for each frame mistake of the case's model.

    cache: a :class:`conformance.judge.oracle.OracleCache` (one oracle per variant frame, reused
    across the states and probes of the same mesh). Raises what the oracle raises.
    """
    h = mean_edge_length(case.points, case.cells)
    out: List[FrameVariant] = []
    for code, title, model in frame_models(case.model, case.cells, case.points):
        variant = CaseInput(case.case_id, case.points, case.cells, case.positions, model)
        ref = cache.reference(variant)
        if any(_same_prediction(v, ref.force, ref.stiffness) for v in out):
            continue
        out.append(
            FrameVariant(
                code,
                title,
                ref.force,
                ref.stiffness,
                scales(h, ref.energy, ref.force, ref.stiffness),
            )
        )
    return out


def _same_prediction(v: FrameVariant, f: np.ndarray, K: sp.spmatrix) -> bool:
    """True when force f (n, 3) and stiffness K (3n, 3n) equal the variant's to round-off."""
    df = float(np.linalg.norm(f - v.force)) / max(v.scales.force, 1e-300)
    dK = float(sparse_norm(sp.csr_matrix(K) - v.stiffness)) / max(v.scales.stiffness, 1e-300)
    return max(df, dK) <= _SAME_PREDICTION
