"""CudaForceField: MJED forces and stiffness on an NVIDIA GPU (Numba CUDA), same API as
:class:`mjed.HyperelasticForceField`, in FP64 (the default) or FP32.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.compiled.lowering import lower_groups
from mjed.compiled.shape import kernel_shape
from mjed.cuda.availability import require_cuda
from mjed.forcefield import check_field_arguments, checked_positions, refuse_inverted
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern

__all__ = ["CudaForceField", "THREADS_PER_BLOCK"]

#: Threads per block of the cell kernel (one thread per cell).
THREADS_PER_BLOCK = 128


class CudaForceField:
    """Nodal forces and tangent stiffness by MJED, one GPU thread per cell.

    Same conventions and methods as :class:`mjed.HyperelasticForceField` (f = -dW/dx (n, 3),
    K = d2W/dx2 as SciPy CSR (3n, 3n) with the pattern of :class:`mjed.sparse.CSRPattern`),
    returned on the host in float64 whatever ``dtype``. The mesh, the material's numbers and
    the per-cell block map of the CSR pattern (:func:`mjed.cuda.codegen.block_map`) are copied
    to the device once; a call copies x in, runs one kernel over the cells and copies f and
    the CSR values out. ``device_force_and_stiffness`` keeps everything on the device (for a
    solver that runs there, and for timing the kernel itself).

    Args:
        mesh, material, regularize, allow_inverted: as :class:`mjed.HyperelasticForceField`.
        dtype: np.float64 (default) or np.float32, the arithmetic and the device arrays.

    Raises:
        BackendUnavailable: Numba or a CUDA device (or the simulator) is missing.
        NotImplementedError: the material has a term kind without a compiled form.
    """

    backend = "cuda"

    def __init__(
        self,
        mesh: TetMesh,
        material: Material,
        *,
        regularize: bool = False,
        allow_inverted: bool = False,
        dtype=np.float64,
    ):
        check_field_arguments(mesh, material)
        cuda = require_cuda()
        from mjed.cuda.codegen import block_map
        from mjed.cuda.kernels import cuda_module, reduce_kernels

        self._cuda = cuda
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.dtype = np.dtype(dtype)
        self.table = lower_groups(material.decomposition(), mesh.D)
        self.shape = kernel_shape(self.table)
        module = cuda_module(self.shape, self.dtype)
        self._kernel, self._force_kernel = module.mjed_cells, module.mjed_force
        self._min_sum, self._zero = reduce_kernels()
        self.pattern = p = CSRPattern(mesh.cells, mesh.n_nodes)
        index = np.int32 if max(p.nnz, 3 * mesh.n_nodes) < 2**31 else np.int64
        blk, rowlen = block_map(mesh.cells, p.indptr, p.indices, mesh.n_nodes)
        dt, t = self.dtype, self.table
        to = cuda.to_device
        self._d = {
            "cells": to(np.ascontiguousarray(mesh.cells, dtype=index)),
            "D": to(np.ascontiguousarray(mesh.D, dtype=dt)),
            "V0": to(np.ascontiguousarray(mesh.volumes, dtype=dt)),
            "numbers": tuple(
                to(np.ascontiguousarray(a, dtype=dt))
                for a in (t.jpar, t.gpar, t.gmat, t.group_coef, t.slot_M)
            ),
            "blk": to(np.ascontiguousarray(blk, dtype=index)),
            "rowlen": to(np.ascontiguousarray(rowlen, dtype=index)),
            "J": cuda.device_array(mesh.n_cells, dtype=dt),
            "E": cuda.device_array(mesh.n_cells, dtype=dt),
            "reduced": cuda.device_array(2, dtype=np.float64),
        }
        self._empty = {
            "force": cuda.device_array((0, 3), dtype=dt),
            "data": cuda.device_array(0, dtype=dt),
            "stress": cuda.device_array((0, 3, 3), dtype=dt),
        }
        self._blocks = max(1, -(-mesh.n_cells // THREADS_PER_BLOCK))

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W at positions x (n, 3)."""
        return self._host(x, force=False, stiffness=False)[0]

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3), float64."""
        return self._host(x, force=True, stiffness=False)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n), float64."""
        return self._host(x, force=False, stiffness=True)[2]

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both from one kernel launch."""
        _, f, K, _ = self._host(x, force=True, stiffness=True)
        return f, K

    def stress(self, x) -> np.ndarray:
        """Second Piola-Kirchhoff stress S = 2 dW/dC per cell, (m, 3, 3), float64."""
        return self._host(x, force=False, stiffness=False, stress=True)[3]

    def force_stiffness_and_stress(self, x):
        """Force (n, 3), stiffness CSR (3n, 3n) and S per cell (m, 3, 3), from one launch."""
        _, f, K, S = self._host(x, force=True, stiffness=True, stress=True)
        return f, K, S

    def device_force_and_stiffness(
        self, x_device, *, force: bool = True, stiffness: bool = True, out: Optional[tuple] = None
    ):
        """F (n, 3) and the CSR values (nnz,) as device arrays of ``dtype``, from positions
        already on the device (n, 3) of ``dtype``; nothing crosses to the host but the minimum
        J and the energy (16 bytes). out: (f, data) device arrays to reuse. Returns
        (energy, f or None, data or None); raises InvertedElementError as the host methods.
        """
        energy, f, data, _ = self._launch(x_device, force, stiffness, False, out)
        return energy, (f if force else None), (data if stiffness else None)

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix of host ``data`` (nnz,) with this field's pattern (owning its indices)."""
        p = self.pattern
        K = sp.csr_matrix(
            (np.asarray(data, dtype=np.float64), p.indices.copy(), p.indptr.copy()),
            shape=p.shape,
            copy=False,
        )
        K.has_sorted_indices = True
        return K

    # ---------------------------------------------------------------- internals
    def _host(self, x, *, force: bool, stiffness: bool, stress: bool = False):
        x = checked_positions(x, self.mesh.n_nodes)
        x_d = self._cuda.to_device(np.ascontiguousarray(x, dtype=self.dtype))
        energy, f, data, S = self._launch(x_d, force, stiffness, stress, None)
        return (
            energy,
            f.copy_to_host().astype(np.float64) if force else None,
            self.matrix(data.copy_to_host()) if stiffness else None,
            S.copy_to_host().astype(np.float64) if stress else None,
        )

    def _launch(self, x_d, force: bool, stiffness: bool, stress: bool, out):
        cuda, d, m, n = self._cuda, self._d, self.mesh.n_cells, self.mesh.n_nodes
        if out is not None:
            f, data = out
        else:
            f = cuda.device_array((n, 3), dtype=self.dtype) if force else self._empty["force"]
            data = (
                cuda.device_array(self.pattern.nnz, dtype=self.dtype)
                if stiffness
                else self._empty["data"]
            )
        if force:
            self._zero_array(f.reshape(3 * n))
        if stiffness:
            self._zero_array(data)
        S = cuda.device_array((m, 3, 3), dtype=self.dtype) if stress else self._empty["stress"]
        if m:
            kernel = self._kernel if stiffness else self._force_kernel
            kernel[self._blocks, THREADS_PER_BLOCK](
                x_d,
                d["cells"],
                d["D"],
                d["V0"],
                *d["numbers"],
                self.regularize,
                force,
                stiffness,
                stress,
                d["blk"],
                d["rowlen"],
                f,
                data,
                d["J"],
                d["E"],
                S,
            )
        J_min, energy = self._reduce()
        if not self.allow_inverted and not J_min > 0.0:
            refuse_inverted(d["J"].copy_to_host())  # names the cells
        return energy, f, data, S

    def _zero_array(self, a) -> None:
        if a.shape[0]:
            self._zero[max(1, min(1024, -(-a.shape[0] // 256))), 256](a)

    def _reduce(self) -> Tuple[float, float]:
        """(min J, sum of the cell energies) over the cells, on the device."""
        m = self.mesh.n_cells
        if m == 0:
            return np.inf, 0.0
        reduced = self._d["reduced"]
        reduced.copy_to_device(np.array([np.inf, 0.0]))
        self._min_sum[max(1, min(256, -(-m // 256))), 256](self._d["J"], self._d["E"], reduced)
        J_min, energy = reduced.copy_to_host()
        return float(J_min), float(energy)
