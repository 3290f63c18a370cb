"""CompiledForceField: MJED forces and stiffness from the compiled kernel, same API as
:class:`mjed.HyperelasticForceField`.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.compiled.assembly import CompiledAssembly
from mjed.compiled.availability import require_numba
from mjed.compiled.lowering import lower_groups
from mjed.compiled.schedule import SLABS_PER_THREAD, cell_schedule
from mjed.compiled.shape import kernel_shape
from mjed.compiled.specialise import kernel_module
from mjed.forcefield import check_field_arguments, checked_positions, refuse_inverted
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = ["CompiledForceField", "kernel_positions"]


def kernel_positions(x, n_nodes: int) -> np.ndarray:
    """X checked (mjed.forcefield.checked_positions) and as a C-contiguous, writeable float64
    (n_nodes, 3) array: Numba compiles one specialisation per array layout and per read-only
    flag (each several seconds), so a view or a read-only array from the caller is copied
    rather than handed to a compiled kernel.
    """
    x = checked_positions(x, n_nodes)
    if not (x.flags.c_contiguous and x.flags.writeable):
        x = np.array(x, order="C")
    return x


class CompiledForceField:
    """Nodal forces and tangent stiffness by MJED, one compiled pass over the cells.

    Same conventions and methods as :class:`mjed.HyperelasticForceField`: f = -dW/dx (n, 3),
    K = d2W/dx2 as SciPy CSR (3n, 3n) with the pattern of :class:`mjed.sparse.CSRPattern`,
    dof = 3 node + component. ``backend`` is "numba".

    Args:
        mesh: the rest mesh.
        material: one of :mod:`mjed.materials` (its declared terms are lowered once, see
            :mod:`mjed.compiled.lowering`).
        regularize: compressed-element regularisation (paper section 2.3), as the NumPy engine.
        allow_inverted: evaluate states with J <= 0 (NaN where ln J appears) instead of raising.
        parallel: run the cells on all of Numba's threads (``numba.set_num_threads`` or
            ``NUMBA_NUM_THREADS`` choose how many): slabs of cells, coloured so that no two
            slabs of a colour share a node (:mod:`mjed.compiled.schedule`), add into the
            same sums without atomics. Same results to round-off (the sums are added in
            another order). The default, one thread, keeps the timing study's comparison
            with the serial classical kernel like for like. Sets ``OMP_WAIT_POLICY=PASSIVE``
            unless it is set (see mjed.compiled.kernels.prefer_passive_wait).
        slabs: slabs of the parallel schedule (default: 4 per thread of Numba's at construction).
        batch: cells per batch of the cell-batched kernel (:mod:`mjed.compiled.batched`: the
            same cell body over ``batch`` cells at once, one per SIMD lane), serial or with
            ``parallel``; 0 (the default) for the kernel that runs one cell at a time. Same
            results (bit for bit: the same operations, added in the same order).

    Cell order: every kernel visits the cells in the order of a
    :class:`mjed.compiled.schedule.CellSchedule` computed once per mesh, one slab in Morton
    order of the centroids when serial, so that consecutive cells add into nearby rows of the
    assembly sums (measured 1.2x faster force + stiffness on cube-paper, whose cells come in
    no spatial order; docs/studies/timing.md). Results are the same to round-off (the sums
    are added in another order); J, S and the cells named by InvertedElementError are in the
    caller's order.

    Raises:
        BackendUnavailable: Numba is not installed.
        NotImplementedError: the material has a term kind without a compiled form.
    """

    backend = "numba"

    def __init__(
        self,
        mesh: TetMesh,
        material: Material,
        *,
        regularize: bool = False,
        allow_inverted: bool = False,
        parallel: bool = False,
        slabs: Optional[int] = None,
        batch: int = 0,
    ):
        check_field_arguments(mesh, material)
        self._k = require_numba()
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.table = lower_groups(material.decomposition(), mesh.D)
        self.shape = kernel_shape(self.table)
        self.parallel = bool(parallel)
        if batch < 0:
            raise ValueError(f"batch must be >= 0, got {batch}")
        self.batch = int(batch)
        module = kernel_module(self.shape, parallel=self.parallel, batch=self.batch)
        self._kernel = module.mjed_cells
        self.pattern = CSRPattern(mesh.cells, mesh.n_nodes)
        self._cells = np.ascontiguousarray(mesh.cells, dtype=np.int64)
        self._D = np.ascontiguousarray(mesh.D, dtype=np.float64)
        self._V0 = np.ascontiguousarray(mesh.volumes, dtype=np.float64)
        self._assembly = CompiledAssembly(self.pattern, self._k)
        self._J = np.empty(mesh.n_cells)
        self._schedule = ()
        if self.parallel:
            self._k.prefer_passive_wait()  # before the thread pool starts
            self.schedule = cell_schedule(
                mesh.points, mesh.cells, slabs or SLABS_PER_THREAD * self._k.threads()
            )
        else:  # one slab: the cells in Morton order (see the class docstring)
            self.schedule = cell_schedule(mesh.points, mesh.cells, 1)
        # every per-cell argument in schedule order, once
        sch = self.schedule
        self._cells, self._D, self._V0 = (
            sch.permute(self._cells),
            sch.permute(self._D),
            sch.permute(self._V0),
        )
        t = self.table
        self._numbers = (
            t.jpar,
            t.gpar,
            sch.permute(t.gmat, axis=1),
            t.group_coef,
            sch.permute(t.slot_M, axis=1),
        )
        a = self._assembly
        self._assembly_args = (
            sch.permute(a.cell_edges),
            sch.permute(a.cell_flip),
        ) + a.arguments()[2:]
        if self.parallel:  # the parallel kernels write J and S at the caller's index cell_id[e]
            self._schedule = sch.arguments()

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W at positions x (n, 3)."""
        return self._run(x, force=False, stiffness=False)[0]

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3)."""
        return self._run(x, force=True, stiffness=False)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n)."""
        return self._run(x, force=False, stiffness=True)[2]

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both from one pass over the cells."""
        _, f, K, _ = self._run(x, force=True, stiffness=True)
        return f, K

    def stress(self, x) -> np.ndarray:
        """Second Piola-Kirchhoff stress S = 2 dW/dC per cell, (m, 3, 3) (Pa, per unit rest
        volume).
        """
        return self._run(x, force=False, stiffness=False, stress=True)[3]

    def force_stiffness_and_stress(self, x) -> Tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
        """Force (n, 3), stiffness CSR (3n, 3n) and S per cell (m, 3, 3), from one pass."""
        _, f, K, S = self._run(x, force=True, stiffness=True, stress=True)
        return f, K, S

    # ---------------------------------------------------------------- internals
    def _run(self, x, *, force: bool, stiffness: bool, stress: bool = False):
        x = kernel_positions(x, self.mesh.n_nodes)
        f = np.zeros((self.mesh.n_nodes, 3)) if force else np.zeros((0, 3))
        data = np.zeros(self.pattern.nnz) if stiffness else np.zeros(0)
        S = np.empty((self.mesh.n_cells if stress else 0, 3, 3))
        energy = self._kernel(
            x,
            self._cells,
            self._D,
            self._V0,
            *self._numbers,
            self.regularize,
            force,
            stiffness,
            stress,
            *self._assembly_args,
            f,
            data,
            self._J,
            S,
            *self._schedule,
        )
        serial = not self.parallel  # its kernels write J and S in schedule order
        if not self.allow_inverted and not (self._J > 0).all():
            refuse_inverted(self.schedule.unpermute(self._J) if serial else self._J)
        if stress and serial:
            S = self.schedule.unpermute(S)
        return (
            float(energy),
            (f if force else None),
            (self._assembly.matrix(data) if stiffness else None),
            (S if stress else None),
        )
