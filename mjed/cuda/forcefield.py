"""CudaForceField: MJED forces and stiffness on an NVIDIA GPU (Numba CUDA), same API as
:class:`mjed.HyperelasticForceField`, in FP64 (the default) or FP32.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.compiled.lowering import lower_groups
from mjed.compiled.shape import kernel_shape
from mjed.cuda.codegen import Assembly
from mjed.cuda.launch import THREADS_PER_BLOCK
from mjed.forcefield import check_field_arguments, checked_positions
from mjed.materials.base import Material
from mjed.mesh import TetMesh

__all__ = ["CudaForceField", "THREADS_PER_BLOCK"]


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
        launcher: a :class:`mjed.cuda.launch.CellLauncher` of this mesh and dtype to share
            (its device arrays) with other fields of the mesh; default a new one.
        assembly: how the stiffness leaves a cell (:class:`mjed.cuda.codegen.Assembly`, or
            its name): "atomic" (the default: atomic adds into the CSR values), "element"
            (per-cell entries, then a gather kernel) or "edge" (the six edge blocks per
            cell, then a gather kernel that forms the rest): the experiments of
            comparisons.timing.gpu_scatter. The results are the same to round-off.

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
        launcher=None,
        assembly=Assembly.ATOMIC,
    ):
        check_field_arguments(mesh, material)
        from mjed.cuda.launch import launcher_for

        # BackendUnavailable first
        self._launcher = launcher = launcher_for(mesh, dtype, launcher)
        from mjed.cuda.kernels import cuda_module

        self._cuda = launcher.cuda
        self.mesh = mesh
        self.material = material
        self.regularize = bool(regularize)
        self.allow_inverted = bool(allow_inverted)
        self.dtype = launcher.dtype
        self.table = lower_groups(material.decomposition(), mesh.D)
        self.shape = kernel_shape(self.table)
        self.assembly = Assembly.of(assembly)
        module = cuda_module(self.shape, self.dtype, self.assembly)
        self._kernel, self._force_kernel = module.mjed_cells, module.mjed_force
        self.pattern = launcher.pattern
        t = self.table
        self._numbers = tuple(
            launcher.to_device(a) for a in (t.jpar, t.gpar, t.gmat, t.group_coef, t.slot_M)
        )
        self._empty_stress = self._cuda.device_array((0, 3, 3), dtype=self.dtype)
        self._ke = None  # the per-cell entries of the element or edge assembly, on first use

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

    def device_element_stiffness(self, x_device, *, force: bool = True, out: tuple):
        """The cell kernel alone of an ``assembly="element"`` or ``"edge"`` field: F (n, 3) and
        the per-cell stiffness entries (144, m) or edge blocks (54, m) into ``out`` = (f, ke),
        device arrays of ``dtype``; no gather (:meth:`mjed.cuda.launch.CellLauncher.gather`
        makes the CSR values of ke). Returns (energy, f, ke). For timing the kernels apart.
        """
        if self.assembly is Assembly.ATOMIC:
            raise ValueError("device_element_stiffness: this field's assembly is atomic")
        return self._cells(x_device, force, True, False, out, self._empty_stress)

    def device_stress(self, x_device, *, out=None):
        """S = 2 dW/dC per cell (m, 3, 3) as a device array of ``dtype``, from positions on the
        device (n, 3) of ``dtype``; out: a device array (m, 3, 3) to reuse. Nothing crosses but
        the minimum J and the energy (16 bytes). Returns (energy, S); raises
        InvertedElementError as the host methods.
        """
        m = self.mesh.n_cells
        S = self._cuda.device_array((m, 3, 3), dtype=self.dtype) if out is None else out
        energy, _, _, S = self._launch(x_device, False, False, True, None, S)
        return energy, S

    @property
    def launcher(self):
        """The :class:`mjed.cuda.launch.CellLauncher` of this field: the mesh (cells, D, V0)
        and the CSR block map (blk, rowlen) on the device, in ``dtype``.
        """
        return self._launcher

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix of host ``data`` (nnz,) with this field's pattern (owning its indices)."""
        return self._launcher.matrix(data)

    # ---------------------------------------------------------------- internals
    def _host(self, x, *, force: bool, stiffness: bool, stress: bool = False):
        x = checked_positions(x, self.mesh.n_nodes)
        energy, f, data, S = self._launch(
            self._launcher.to_device(x), force, stiffness, stress, None
        )
        return (
            energy,
            f.copy_to_host().astype(np.float64) if force else None,
            self.matrix(data.copy_to_host()) if stiffness else None,
            S.copy_to_host().astype(np.float64) if stress else None,
        )

    def _cells(self, x_d, force: bool, stiffness: bool, stress: bool, out, S):
        """One launch of the cell kernel (the stiffness one when asked): (energy, f, CSR
        values or, for the element assembly, the per-cell entries).
        """
        return self._launcher.launch(
            self._kernel if stiffness else self._force_kernel,
            x_d,
            self._numbers,
            (self.regularize, force, stiffness, stress),
            force=force,
            stiffness=stiffness,
            allow_inverted=self.allow_inverted,
            out=out,
            tail=(S,),
            assembly=self.assembly if stiffness else Assembly.ATOMIC,
        )

    def _new_force(self, force: bool):
        n = self.mesh.n_nodes
        if force:
            return self._cuda.device_array((n, 3), dtype=self.dtype)
        return self._launcher.empty_force

    def _launch(self, x_d, force: bool, stiffness: bool, stress: bool, out, S=None):
        m = self.mesh.n_cells
        if S is None:
            S = self._empty_stress
            if stress:
                S = self._cuda.device_array((m, 3, 3), dtype=self.dtype)
        element = stiffness and self.assembly is not Assembly.ATOMIC
        csr = None if out is None else out[1]
        if element:  # the cell kernel stores into ke, the gather writes the CSR values
            if self._ke is None:
                shape = (self.assembly.entries, m)
                self._ke = self._cuda.device_array(shape, dtype=self.dtype)
            f = out[0] if out is not None else self._new_force(force)
            out = (f, self._ke)
        energy, f, data_or_ke = self._cells(x_d, force, stiffness, stress, out, S)
        if element:
            data_or_ke = self._launcher.gather(data_or_ke, csr, self.assembly)
        return energy, f, data_or_ke, S
