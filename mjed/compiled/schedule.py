"""The order in which the parallel CPU kernel visits the cells: slabs of cells, coloured so
that the slabs of one colour share no node (computed once per mesh).

The cells are cut into ``slabs`` slabs of equal cell counts along the mesh's longest extent
(by the rank of their centroid's coordinate), each slab's cells sorted along a Morton
(Z-order) curve of their centroids, and the slabs are coloured greedily
(:func:`mjed.compiled.kernels.colour_chunks`); the slabs are then laid out colour by colour.
The parallel kernel (:class:`mjed.compiled.codegen.ParallelTarget`) runs the slabs of one
colour on all threads, each slab's cells in order, and the colours one after the other.

Why slabs: each colour is one parallel loop, hence one synchronisation of all threads, and
on a machine shared with other work a thread that is descheduled holds every other one at
that point; the colours must be few. Slabs thicker than a cell touch only their two
neighbours, so two colours suffice (cube-paper, 20,599 cells: 2 colours for 4 or 8 slabs,
3 for 16). Colouring single cells takes 44 colours there, the last ones a handful of cells
each, and Morton-sorted chunks of 32 cells 18. The Morton order inside a slab keeps the
nodes and edges a thread visits in a row close in memory: with one thread the reordered
kernel already runs 15 to 20 % faster than the serial kernel in the mesh's own cell order,
so the serial kernels (one cell at a time and batched, and the compiled classical element)
run the schedule of one slab: the cells in Morton order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CellSchedule", "cell_schedule", "morton_order", "SLABS_PER_THREAD"]

#: Slabs per thread of the parallel CPU kernel: two colours of two slabs per thread each
#: balance the work when slabs are uneven and keep the synchronisations at two or three.
SLABS_PER_THREAD = 4


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """The bits of v (< 2^21) spread to every third bit."""
    v = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    out = np.zeros_like(v)
    for b in range(21):
        out |= ((v >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b)
    return out


def morton_order(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The permutation sorting the cells along the Morton curve of their centroids."""
    c = np.asarray(points, float)[np.asarray(cells)].mean(axis=1)
    lo, span = c.min(axis=0), np.ptp(c, axis=0)
    q = ((c - lo) / np.where(span > 0, span, 1.0) * (2**21 - 1)).astype(np.int64)
    code = (
        _spread_bits(q[:, 0])
        | (_spread_bits(q[:, 1]) << np.uint64(1))
        | (_spread_bits(q[:, 2]) << np.uint64(2))
    )
    return np.argsort(code, kind="stable")


@dataclass(frozen=True)
class CellSchedule:
    """cell_id (m,): the caller's index of the cell at each schedule position (so a per-cell
    array ``a`` in schedule order is ``a[cell_id]``); chunk_ptr (chunks + 1,), colour_ptr
    (colours + 1,): see :class:`mjed.compiled.codegen.ParallelTarget`.
    """

    cell_id: np.ndarray
    chunk_ptr: np.ndarray
    colour_ptr: np.ndarray

    @property
    def n_colours(self) -> int:
        return len(self.colour_ptr) - 1

    def arguments(self):
        return self.cell_id, self.chunk_ptr, self.colour_ptr

    def permute(self, per_cell: np.ndarray, axis: int = 0) -> np.ndarray:
        """``per_cell`` (cell axis ``axis``) in schedule order, C-contiguous; an axis of length
        one (a value shared by every cell) is left as it is.
        """
        if per_cell.shape[axis] == 1:
            return np.ascontiguousarray(per_cell)
        return np.ascontiguousarray(np.take(per_cell, self.cell_id, axis=axis))

    def unpermute(self, per_cell: np.ndarray) -> np.ndarray:
        """A per-cell array (cell axis first) from schedule order back to the caller's order."""
        out = np.empty_like(per_cell)
        out[self.cell_id] = per_cell
        return out


def cell_schedule(points: np.ndarray, cells: np.ndarray, slabs: int) -> CellSchedule:
    """The schedule of a mesh: ``slabs`` slabs of equal cell counts along the mesh's longest
    extent (each slab's cells in Morton order), laid out by colour (see the module docstring).
    Correct for any mesh and any ``slabs`` >= 1 (the colouring, not the geometry, guarantees
    that no two slabs of a colour share a node; thin slabs only cost more colours).
    """
    from mjed.compiled.kernels import colour_chunks

    if slabs < 1:
        raise ValueError(f"slabs must be >= 1, got {slabs}")
    cells = np.asarray(cells, dtype=np.int64)
    m = len(cells)
    order = morton_order(points, cells) if m else np.zeros(0, np.int64)
    centroid = np.asarray(points, float)[cells].mean(axis=1)
    axis = int(np.argmax(np.ptp(centroid, axis=0))) if m else 0
    rank = np.empty(m, dtype=np.int64)
    rank[np.argsort(centroid[:, axis], kind="stable")] = np.arange(m)
    slab = rank * slabs // max(m, 1)
    pos = np.empty(m, dtype=np.int64)
    pos[order] = np.arange(m)
    order = np.lexsort((pos, slab))
    ptr = np.unique(np.searchsorted(slab[order], np.arange(slabs + 1)).astype(np.int64))
    colour = colour_chunks(
        np.ascontiguousarray(cells[order]), ptr, len(points)
    )  # the colour of each slab
    by_colour = np.argsort(colour, kind="stable")  # slabs laid out colour by colour
    sizes = np.diff(ptr)[by_colour]
    cell_id = (
        np.concatenate([order[ptr[k] : ptr[k + 1]] for k in by_colour])
        if m
        else np.zeros(0, np.int64)
    )
    chunk_ptr = np.zeros(len(by_colour) + 1, dtype=np.int64)
    np.cumsum(sizes, out=chunk_ptr[1:])
    counts = np.bincount(colour, minlength=int(colour.max()) + 1 if len(colour) else 0)
    colour_ptr = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=colour_ptr[1:])
    return CellSchedule(cell_id.astype(np.int64), chunk_ptr, colour_ptr)
