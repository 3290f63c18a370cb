"""The CUDA modules: the generated cell kernel of a shape (one per dtype) and the two small
fixed kernels a launch uses (the minimum J and the energy sum; zeroing an array, which is
:func:`mjed.cuda.step_kernels.fill_zero`). Importing this module imports numba.cuda.
"""

from __future__ import annotations

from functools import lru_cache
from types import ModuleType

import numpy as np
from numba import cuda

from mjed.compiled.codegen import kernel_source
from mjed.compiled.shape import KernelShape
from mjed.compiled.specialise import generated_module
from mjed.cuda.codegen import CudaTarget
from mjed.cuda.step_kernels import fill_zero

__all__ = ["cuda_module", "reduce_kernels"]


def cuda_module(shape: KernelShape, dtype=np.float64) -> ModuleType:
    """The module of the CUDA kernel of ``shape`` in ``dtype`` (its kernel ``mjed_cells``),
    written to the kernel cache directory (mjed.compiled.specialise) and imported; Numba
    compiles it for the device on its first launch.
    """
    target = CudaTarget(dtype)
    return generated_module(kernel_source(shape, target), f"mjed_cuda_{target.dtype.name}")


@cuda.jit
def _min_and_sum(J, E, out):
    """out[0] = min(out[0], min J), out[1] += sum E (float64), grid-stride, one atomic of each
    per thread.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    lo = np.inf
    total = 0.0
    for i in range(start, J.shape[0], stride):
        v = np.float64(J[i])
        if not v > lo:  # NaN propagates as a non-positive J would
            lo = v if v == v else -np.inf
        total += np.float64(E[i])
    cuda.atomic.min(out, 0, lo)
    cuda.atomic.add(out, 1, total)


@lru_cache(maxsize=None)
def reduce_kernels():
    """(min_and_sum, zero): the fixed kernels."""
    return _min_and_sum, fill_zero
