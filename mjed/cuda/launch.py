"""What every one-thread-per-cell kernel of the cuda backend needs around it: the mesh and the
CSR block map on the device, the launch, the zeroing of the outputs and the reduction of J
and the energy (:class:`CellLauncher`).

A kernel launched here takes ``(x, cells, D, V0, *head, *flags, blk, rowlen, force, data,
J_out, E_out, *tail)``: the positions and the rest geometry, its own numbers (``head``: the
MJED term tables, or the classical law's parameters), what to form (``flags``), the block
map of the CSR pattern (:func:`mjed.cuda.codegen.block_map`), the outputs and any further
ones (``tail``: the MJED stress). The MJED field (:mod:`mjed.cuda.forcefield`) and the
classical element on the GPU (reference_fem.classical_cuda) both run through it.

A kernel generated with :attr:`mjed.cuda.codegen.Assembly.ELEMENT` takes, in place of the CSR
values, the per-cell stiffness entries (144, m) (``launch(..., assembly=...)``), which
:meth:`CellLauncher.gather` sums into the CSR values through the mesh's
:class:`mjed.cuda.codegen.ElementIncidence` (built on the host and copied on first use); one
generated with :attr:`mjed.cuda.codegen.Assembly.EDGE`, its six edge blocks per cell (54, m),
which ``gather(..., assembly=EDGE)`` turns into the CSR values through the
:class:`mjed.cuda.codegen.EdgeIncidence`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.cuda.availability import require_cuda
from mjed.cuda.codegen import (
    BLOCK_ENTRIES,
    EDGE_ENTRIES,
    Assembly,
    EdgeIncidence,
    ElementIncidence,
)
from mjed.cuda.threads import REDUCTION_BLOCKS, THREADS_PER_BLOCK, ZEROING_BLOCKS, blocks_for
from mjed.forcefield import refuse_inverted
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = ["BlockLayout", "CellLauncher", "THREADS_PER_BLOCK", "launcher_for"]


@dataclass(frozen=True)
class BlockLayout:
    """The host side of a mesh's CSR assembly on the device: the pattern, the block map
    (m, 16) and the row length per node (:func:`mjed.cuda.codegen.block_map`). Built once per
    mesh; launchers of several dtypes (and several fields) of one mesh may share it.
    """

    pattern: CSRPattern
    blk: np.ndarray
    rowlen: np.ndarray

    @classmethod
    def of(cls, mesh: TetMesh) -> "BlockLayout":
        from mjed.cuda.codegen import block_map

        pattern = CSRPattern(mesh.cells, mesh.n_nodes)
        blk, rowlen = block_map(mesh.cells, pattern.indptr, pattern.indices, mesh.n_nodes)
        return cls(pattern, blk, rowlen)

    @cached_property
    def incidence(self) -> ElementIncidence:
        """The CSR-block -> cell-entry incidence of the element assembly, built on first use
        (:func:`mjed.cuda.codegen.element_incidence`).
        """
        from mjed.cuda.codegen import element_incidence

        p = self.pattern
        return element_incidence(self.blk, p.indptr, p.shape[0] // 3)

    @cached_property
    def edge_incidence(self) -> EdgeIncidence:
        """The CSR-block -> stored edge block incidence of the edge assembly, built on first
        use from :attr:`incidence` (:func:`mjed.cuda.codegen.edge_incidence`).
        """
        from mjed.cuda.codegen import edge_incidence

        return edge_incidence(self.incidence)


class CellLauncher:
    """The device side of one mesh in ``dtype``: cells, D, V0, the block map of the CSR
    pattern (:class:`mjed.sparse.CSRPattern`), J and the energy per cell, copied or allocated
    once; :meth:`launch` runs a cell kernel and checks J. Fields of one mesh and dtype (the
    MJED and the classical one, say) may share one launcher, hence its device arrays;
    ``layout`` shares the host side between dtypes.
    """

    def __init__(self, mesh: TetMesh, dtype=np.float64, layout: Optional[BlockLayout] = None):
        cuda = require_cuda()
        from mjed.cuda.kernels import reduce_kernels

        self.cuda = cuda
        self.mesh = mesh
        self.dtype = dt = np.dtype(dtype)
        self._min_sum, self._zero = reduce_kernels()
        self.layout = layout = BlockLayout.of(mesh) if layout is None else layout
        self.pattern = p = layout.pattern
        if p.shape[0] != 3 * mesh.n_nodes or len(layout.blk) != mesh.n_cells:
            raise ValueError("CellLauncher: the block layout is not this mesh's")
        #: the integer type of the connectivity and the block map on the device
        self.index = np.int32 if max(p.nnz, 3 * mesh.n_nodes) < 2**31 else np.int64
        blk, rowlen = layout.blk, layout.rowlen
        to = cuda.to_device
        self.cells = to(np.ascontiguousarray(mesh.cells, dtype=self.index))
        self.D = to(np.ascontiguousarray(mesh.D, dtype=dt))
        self.V0 = to(np.ascontiguousarray(mesh.volumes, dtype=dt))
        self.blk = to(np.ascontiguousarray(blk, dtype=self.index))
        self.rowlen = to(np.ascontiguousarray(rowlen, dtype=self.index))
        self.J = cuda.device_array(mesh.n_cells, dtype=dt)
        self.E = cuda.device_array(mesh.n_cells, dtype=dt)
        self._reduced = cuda.device_array(2, dtype=np.float64)
        self.empty_force = cuda.device_array((0, 3), dtype=dt)
        self.empty_data = cuda.device_array(0, dtype=dt)
        self.blocks = blocks_for(mesh.n_cells)

    def to_device(self, a) -> object:
        """A host array on the device, in this launcher's dtype."""
        return self.cuda.to_device(np.ascontiguousarray(a, dtype=self.dtype))

    def launch(
        self,
        kernel,
        x_d,
        head: tuple,
        flags: tuple,
        *,
        force: bool,
        stiffness: bool,
        allow_inverted: bool,
        out: Optional[tuple] = None,
        tail: tuple = (),
        assembly: Assembly = Assembly.ATOMIC,
    ):
        """Run ``kernel`` over the cells (see the module docstring for its arguments) into
        fresh force (n, 3) and CSR values (nnz,), zeroed, or into ``out`` = (f, data).
        With ``assembly`` ELEMENT or EDGE (a kernel generated so), data is the per-cell
        entries (144, m) or edge blocks (54, m), not zeroed (every entry is stored).
        Returns (energy, f, data); raises InvertedElementError, naming the cells, for
        J <= 0 unless ``allow_inverted``.
        """
        cuda, m, n = self.cuda, self.mesh.n_cells, self.mesh.n_nodes
        assembly = Assembly.of(assembly)
        atomic = assembly is Assembly.ATOMIC
        if out is not None:
            f, data = out
        else:
            f = cuda.device_array((n, 3), dtype=self.dtype) if force else self.empty_force
            shape = self.pattern.nnz if atomic else (assembly.entries, m)
            data = cuda.device_array(shape, dtype=self.dtype) if stiffness else self.empty_data
        if force:
            self._zero_array(f.reshape(3 * n))
        if stiffness and atomic:
            self._zero_array(data)
        if m:
            kernel[self.blocks, THREADS_PER_BLOCK](
                x_d,
                self.cells,
                self.D,
                self.V0,
                *head,
                *flags,
                self.blk,
                self.rowlen,
                f,
                data,
                self.J,
                self.E,
                *tail,
            )
        J_min, energy = self._reduce()
        if not allow_inverted and not J_min > 0.0:
            refuse_inverted(self.J.copy_to_host())  # names the cells
        return energy, f, data

    def gather(self, ke, data=None, assembly: Assembly = Assembly.ELEMENT):
        """The CSR values (nnz,) on the device, into ``data`` or a fresh array, from the
        per-cell entries ``ke`` of an ELEMENT kernel (144, m) or the edge blocks of an EDGE
        kernel (54, m) (``assembly``): one thread per 3x3 block of the pattern
        (:func:`mjed.cuda.kernels.gather_blocks`, :func:`mjed.cuda.kernels.gather_edge_blocks`).
        Returns data.
        """
        from mjed.cuda import kernels

        assembly = Assembly.of(assembly)
        if assembly is Assembly.ATOMIC:
            raise ValueError("gather: the atomic assembly has nothing to gather")
        if data is None:
            data = self.cuda.device_array(self.pattern.nnz, dtype=self.dtype)
        edge = assembly is Assembly.EDGE
        inc = self._edge_incidence if edge else self._incidence
        blocks = len(inc[-2])
        m = self.mesh.n_cells
        if blocks and m:
            kernel = kernels.gather_edge_blocks if edge else kernels.gather_blocks
            kernel[blocks_for(blocks), THREADS_PER_BLOCK](
                ke.reshape(assembly.entries * m), *inc, m, data
            )
        return data

    def _device_incidence(self, inc: ElementIncidence, codes: int, extra: tuple) -> tuple:
        """The incidence's integer arrays on the device: (offsets, contributions, *extra,
        first, rowlen), int32 while ``codes`` and the contributions fit, as the mesh's.
        """
        big = max(inc.offsets[-1], codes) >= 2**31
        index = np.int64 if big or self.index == np.int64 else np.int32
        arrays = (inc.offsets, inc.contributions, *extra, inc.first, inc.rowlen)
        return tuple(self.cuda.to_device(np.ascontiguousarray(a, dtype=index)) for a in arrays)

    @cached_property
    def _incidence(self) -> tuple:
        """(offsets, contributions, first, rowlen) of the layout's incidence on the device."""
        m = self.mesh.n_cells
        return self._device_incidence(self.layout.incidence, BLOCK_ENTRIES * m, ())

    @cached_property
    def _edge_incidence(self) -> tuple:
        """(offsets, contributions, diagonal, first, rowlen) of the layout's edge incidence on
        the device (the codes 2 q + t reach 2 * 54 m).
        """
        inc = self.layout.edge_incidence
        m = self.mesh.n_cells
        return self._device_incidence(inc, 2 * EDGE_ENTRIES * m, (inc.diagonal,))

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix of host ``data`` (nnz,) with this mesh's pattern (owning its indices)."""
        p = self.pattern
        K = sp.csr_matrix(
            (np.asarray(data, dtype=np.float64), p.indices.copy(), p.indptr.copy()),
            shape=p.shape,
            copy=False,
        )
        K.has_sorted_indices = True
        return K

    def _zero_array(self, a) -> None:
        if a.shape[0]:
            self._zero[blocks_for(a.shape[0], ZEROING_BLOCKS), THREADS_PER_BLOCK](a)

    def _reduce(self) -> Tuple[float, float]:
        """(min J, sum of the cell energies) over the cells, on the device."""
        m = self.mesh.n_cells
        if m == 0:
            return np.inf, 0.0
        self._reduced.copy_to_device(np.array([np.inf, 0.0]))
        grid = blocks_for(m, REDUCTION_BLOCKS)
        self._min_sum[grid, THREADS_PER_BLOCK](self.J, self.E, self._reduced)
        J_min, energy = self._reduced.copy_to_host()
        return float(J_min), float(energy)


def launcher_for(mesh: TetMesh, dtype, launcher: Optional[CellLauncher]) -> CellLauncher:
    """``launcher`` when given (checked to be of ``mesh`` and ``dtype``), else a new one."""
    if launcher is None:
        return CellLauncher(mesh, dtype)
    if launcher.mesh is not mesh or launcher.dtype != np.dtype(dtype):
        raise ValueError(
            f"the launcher given is of another mesh or dtype ({launcher.dtype.name}, asked "
            f"{np.dtype(dtype).name}): pass one built for this mesh and dtype"
        )
    return launcher
