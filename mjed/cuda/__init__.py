"""The optional CUDA backend of mjed (Numba's CUDA target), FP64 or FP32.

    >>> from mjed.cuda import CudaForceField
    >>> field = CudaForceField(mesh, material)                  # FP64
    >>> field32 = CudaForceField(mesh, material, dtype=np.float32)
    >>> f, K = field.force_and_stiffness(x)                     # same methods as
    HyperelasticForceField

or ``mjed.make_force_field(mesh, material, backend="cuda", dtype=...)``.

The kernels are generated from the material's declared terms by the generator of the CPU
kernels (:mod:`mjed.compiled.codegen`) with a CUDA target (:mod:`mjed.cuda.codegen`): one
thread per cell, the stiffness added straight into the CSR values through a block map
computed once per mesh, and a second kernel without the stiffness code for the force alone.
Without a GPU they run on Numba's CUDA simulator when ``NUMBA_ENABLE_CUDASIM=1`` is set
before Numba is imported (tests/test_cuda.py does so, in a subprocess), and compile to PTX
wherever a CUDA toolkit's NVVM is found (tests/test_cuda_ptx.py); otherwise building a field
raises :class:`BackendUnavailable` saying why. Importing :mod:`mjed` or this package does not
import Numba.

Implicit Euler with the whole step on the device (forces, CSR values, the step matrix, the
right-hand side, the constraints, CG and the update; the viscous history and the porous
model's fluid pressure in :mod:`mjed.cuda.device_models`):
:class:`mjed.cuda.integrator.DeviceImplicitEuler`, or
:func:`mjed.cuda.integrator.implicit_euler`, which gives it where the models allow and the
host integrator otherwise. Speed on a GPU (an H200, 26 November 2026): docs/studies/timing.md,
"Measured on an NVIDIA H200".
"""

from mjed.compiled.availability import BackendUnavailable
from mjed.cuda.availability import cuda_available, require_cuda, simulated
from mjed.cuda.forcefield import CudaForceField

__all__ = ["CudaForceField", "BackendUnavailable", "cuda_available", "require_cuda", "simulated"]
