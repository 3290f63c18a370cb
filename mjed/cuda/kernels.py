"""The CUDA modules: the generated cell kernel of a shape (one per dtype and
:class:`mjed.cuda.codegen.Assembly`) and the small fixed kernels a launch uses (the minimum J
and the energy sum; zeroing an array, which is :func:`mjed.cuda.step_kernels.fill_zero`; the
gather of per-cell stiffness entries into the CSR values, :func:`gather_blocks`, and of
per-cell edge blocks, :func:`gather_edge_blocks`). Importing
this module imports numba.cuda.
"""

from __future__ import annotations

from functools import lru_cache
from types import ModuleType

import numpy as np
from numba import cuda

from mjed.compiled.codegen import kernel_source
from mjed.compiled.shape import KernelShape
from mjed.compiled.specialise import generated_module
from mjed.cuda.codegen import Assembly, CudaTarget
from mjed.cuda.step_kernels import fill_zero

__all__ = ["cuda_module", "gather_blocks", "gather_edge_blocks", "reduce_kernels"]


def cuda_module(shape: KernelShape, dtype=np.float64, assembly=Assembly.ATOMIC) -> ModuleType:
    """The module of the CUDA kernel of ``shape`` in ``dtype`` with the stiffness leaving a
    cell as ``assembly`` says (its kernel ``mjed_cells``), written to the kernel cache
    directory (mjed.compiled.specialise) and imported; Numba compiles it for the device on its
    first launch. The assembly is part of the file's name as well as of its source.
    """
    target = CudaTarget(dtype, assembly)
    suffix = "" if target.assembly is Assembly.ATOMIC else f"_{target.assembly.value}"
    return generated_module(kernel_source(shape, target), f"mjed_cuda_{target.dtype.name}{suffix}")


@cuda.jit
def gather_blocks(ke, offsets, contributions, first, rowlen, m, data):
    """The CSR values ``data`` from the per-cell stiffness entries ``ke`` (144 m, the
    (144, m) array of :attr:`mjed.cuda.codegen.Assembly.ELEMENT` read flat), one thread per
    3x3 block t of the pattern: the sum of its contributions (offsets[t]:offsets[t + 1] of
    ``contributions``, entry (r, c) at contributions[k] + (3 r + c) m) written at first[t] +
    r rowlen[t] + c (:class:`mjed.cuda.codegen.ElementIncidence`). Every block of a pattern
    has a contribution, so every value is written: ``data`` needs no zeroing. The sums start
    from the first contribution, so that they stay in the dtype of ``ke``.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for t in range(start, first.shape[0], stride):
        k0 = offsets[t]
        q = contributions[k0]
        s0, s1, s2 = ke[q], ke[q + m], ke[q + 2 * m]
        s3, s4, s5 = ke[q + 3 * m], ke[q + 4 * m], ke[q + 5 * m]
        s6, s7, s8 = ke[q + 6 * m], ke[q + 7 * m], ke[q + 8 * m]
        for k in range(k0 + 1, offsets[t + 1]):
            q = contributions[k]
            s0 += ke[q]
            s1 += ke[q + m]
            s2 += ke[q + 2 * m]
            s3 += ke[q + 3 * m]
            s4 += ke[q + 4 * m]
            s5 += ke[q + 5 * m]
            s6 += ke[q + 6 * m]
            s7 += ke[q + 7 * m]
            s8 += ke[q + 8 * m]
        p, L = first[t], rowlen[t]
        data[p], data[p + 1], data[p + 2] = s0, s1, s2
        data[p + L], data[p + L + 1], data[p + L + 2] = s3, s4, s5
        data[p + 2 * L], data[p + 2 * L + 1], data[p + 2 * L + 2] = s6, s7, s8


@cuda.jit
def gather_edge_blocks(ke, offsets, contributions, diagonal, first, rowlen, m, data):
    """The CSR values ``data`` from the per-cell edge blocks ``ke`` (54 m, the (54, m) array
    of :attr:`mjed.cuda.codegen.Assembly.EDGE` read flat), one thread per 3x3 block t of the
    pattern: the sum of its contributions (offsets[t]:offsets[t + 1] of ``contributions``,
    each 2 q + transposed: entry (r, c) at q + (3 r + c) m, or q + (3 c + r) m transposed),
    negated for a diagonal block (``diagonal[t]``), written at first[t] + r rowlen[t] + c
    (:class:`mjed.cuda.codegen.EdgeIncidence`). Every value is written: ``data`` needs no
    zeroing. The sums start from the first contribution, so that they stay in the dtype of
    ``ke``.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for t in range(start, first.shape[0], stride):
        k0 = offsets[t]
        code = contributions[k0]
        q = code >> 1
        R = m + 2 * m * (1 - (code & 1))  # the stride of a row: 3 m as stored, m transposed
        C = 4 * m - R
        s0, s1, s2 = ke[q], ke[q + C], ke[q + 2 * C]
        s3, s4, s5 = ke[q + R], ke[q + R + C], ke[q + R + 2 * C]
        s6, s7, s8 = ke[q + 2 * R], ke[q + 2 * R + C], ke[q + 2 * R + 2 * C]
        for k in range(k0 + 1, offsets[t + 1]):
            code = contributions[k]
            q = code >> 1
            R = m + 2 * m * (1 - (code & 1))
            C = 4 * m - R
            s0 += ke[q]
            s1 += ke[q + C]
            s2 += ke[q + 2 * C]
            s3 += ke[q + R]
            s4 += ke[q + R + C]
            s5 += ke[q + R + 2 * C]
            s6 += ke[q + 2 * R]
            s7 += ke[q + 2 * R + C]
            s8 += ke[q + 2 * R + 2 * C]
        if diagonal[t]:
            s0, s1, s2, s3, s4, s5, s6, s7, s8 = -s0, -s1, -s2, -s3, -s4, -s5, -s6, -s7, -s8
        p, L = first[t], rowlen[t]
        data[p], data[p + 1], data[p + 2] = s0, s1, s2
        data[p + L], data[p + L + 1], data[p + L + 2] = s3, s4, s5
        data[p + 2 * L], data[p + 2 * L + 1], data[p + 2 * L + 2] = s6, s7, s8


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
