"""The classical Galerkin on an NVIDIA GPU (Numba CUDA), FP64 or FP32: the like-for-like
opponent of :class:`mjed.cuda.CudaForceField`.

The kernel of each law's :class:`reference_fem.classical_codegen.LawShape` is written by the
generator of the CPU classical kernel with a CUDA target
(:class:`reference_fem.classical_codegen.ClassicalCudaTarget`): one thread per cell, the
force by atomic adds, every block added straight into the CSR values through the per-mesh
block map, a second kernel without the stiffness code for the force alone; it is launched
by the MJED field's machinery (:class:`mjed.cuda.launch.CellLauncher`: same mesh arrays,
same block map, same CSR pattern, same reductions), so the two differ only in the cell
body. The laws are lowered to a shape and parameters as for the compiled CPU element
(:func:`reference_fem.classical_compiled.lower_law`). Without a GPU it runs on Numba's CUDA
simulator when ``NUMBA_ENABLE_CUDASIM=1`` is set before Numba is imported.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.forcefield import checked_positions
from mjed.mesh import TetMesh
from reference_fem import classical_materials as cm
from reference_fem.classical_codegen import ClassicalCudaTarget, classical_source
from reference_fem.classical_compiled import lower_law

__all__ = ["CudaClassicalGalerkin"]


class CudaClassicalGalerkin:
    """Energy, forces and tangent stiffness by the classical Total Lagrangian FEM on the GPU.

    Same arguments and methods as :class:`reference_fem.classical.ClassicalGalerkin` (points
    may be an mjed.TetMesh with cells=None), plus ``dtype`` (np.float64 or np.float32, the
    arithmetic and the device arrays; host results are float64), ``launcher`` (a
    :class:`mjed.cuda.launch.CellLauncher` of this mesh and dtype, e.g. the MJED field's, whose
    device mesh arrays are then shared), ``allow_inverted`` and
    ``device_force_and_stiffness`` (as :class:`mjed.cuda.CudaForceField`'s). ``backend`` is
    "cuda". Raises BackendUnavailable without Numba's CUDA target and a device (or the
    simulator), InvertedElementError for J <= 0.
    """

    backend = "cuda"

    def __init__(
        self,
        points,
        cells,
        material,
        *,
        fix_orientation: bool = False,
        dtype=np.float64,
        allow_inverted: bool = False,
        launcher=None,
    ):
        if isinstance(points, TetMesh):
            if cells is not None:
                raise ValueError("pass either a TetMesh (with cells=None) or points and cells")
            self.mesh = points
        else:
            self.mesh = TetMesh(points, cells, fix_orientation=fix_orientation)
        frame = getattr(material, "frame", None)
        if frame is not None and np.ndim(frame) == 3 and len(frame) != self.mesh.n_cells:
            raise ValueError(
                f"Costa frame has {len(frame)} rotations for {self.mesh.n_cells} cells"
            )
        from mjed.cuda.launch import launcher_for

        # BackendUnavailable first
        self._launcher = launcher = launcher_for(self.mesh, dtype, launcher)
        from mjed.compiled.specialise import generated_module

        self.material = material
        self.dtype = launcher.dtype
        self.allow_inverted = bool(allow_inverted)
        self.law = cm.classical_law(material)
        self.shape, params, tensor = lower_law(self.law)
        target = ClassicalCudaTarget(self.dtype)
        module = generated_module(
            classical_source(self.shape, target), f"classical_cuda_{self.dtype.name}"
        )
        self._kernel, self._force_kernel = module.classical_cells, module.classical_force
        self.pattern = launcher.pattern
        self._numbers = (launcher.to_device(params), launcher.to_device(tensor))

    def energy(self, x) -> float:
        return self._host(x, False, False)[0]

    def force(self, x) -> np.ndarray:
        return self._host(x, True, False)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        return self._host(x, False, True)[2]

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        _, f, K = self._host(x, True, True)
        return f, K

    def device_force_and_stiffness(
        self, x_device, *, force: bool = True, stiffness: bool = True, out: Optional[tuple] = None
    ):
        """(energy, F (n, 3) or None, CSR values (nnz,) or None), device arrays of ``dtype``,
        from positions already on the device; out: (f, data) device arrays to reuse.
        """
        energy, f, data = self._launch(x_device, force, stiffness, out)
        return energy, (f if force else None), (data if stiffness else None)

    def _host(self, x, force: bool, stiffness: bool):
        x = checked_positions(x, self.mesh.n_nodes)
        energy, f, data = self._launch(self._launcher.to_device(x), force, stiffness, None)
        return (
            energy,
            f.copy_to_host().astype(np.float64) if force else None,
            self._launcher.matrix(data.copy_to_host()) if stiffness else None,
        )

    def _launch(self, x_d, force: bool, stiffness: bool, out):
        return self._launcher.launch(
            self._kernel if stiffness else self._force_kernel,
            x_d,
            self._numbers,
            (force, stiffness),
            force=force,
            stiffness=stiffness,
            allow_inverted=self.allow_inverted,
            out=out,
        )
