"""Compile the generated CUDA kernels to PTX with libNVVM, without a GPU, and print what the
PTX holds as JSON (tests/test_cuda_ptx.py runs this in a subprocess). Needs a CUDA toolkit's
NVVM (e.g. CUDA_HOME pointing at one, or PyPI's nvidia-cuda-nvcc-cu11 unpacked); prints
{"nvvm": false, ...} when there is none.

    CUDA_HOME=/path/to/cuda NUMBA_FORCE_CUDA_CC=8.0 python tests/cuda_ptx.py [MATERIAL ...]

Two adjustments let Numba 0.56 compile for a device it cannot see: NUMBA_FORCE_CUDA_CC picks
the architecture (it would otherwise ask the CUDA runtime which ones the toolkit supports),
and the lowering of a double-precision atomic add, which asks the current device whether it
has one (compute capability >= 6.0), is told that it has.
"""

from __future__ import annotations

import json
import sys
import types

import numpy as np


def main(names) -> dict:
    try:
        from numba.cuda.cudadrv.nvvm import NVVM

        NVVM()
    except Exception as exc:  # no libNVVM here
        return {"nvvm": False, "reason": str(exc).splitlines()[0]}
    import numba.cuda.nvvmutils as nvvmutils

    if hasattr(nvvmutils, "current_context"):  # Numba 0.56: double atomics ask the device
        device = types.SimpleNamespace(compute_capability=(8, 0))
        nvvmutils.current_context = lambda: types.SimpleNamespace(device=device)
    from conftest import MATERIALS
    from numba import cuda
    from numba import types as nt

    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape
    from mjed.cuda import kernels

    def signature(dtype):
        f = nt.float64 if dtype == np.float64 else nt.float32
        a = lambda t, nd: nt.Array(t, nd, "C")  # noqa: E731
        i = nt.int32
        return (
            a(f, 2),
            a(i, 2),
            a(f, 3),
            a(f, 1),
            a(f, 2),
            a(f, 2),
            a(f, 4),
            a(f, 1),
            a(f, 4),
            nt.boolean,
            nt.boolean,
            nt.boolean,
            nt.boolean,
            a(i, 2),
            a(i, 1),
            a(f, 2),
            a(f, 1),
            a(f, 1),
            a(f, 1),
            a(f, 3),
        )

    out = {"nvvm": True, "kernels": []}
    for name in names:
        shape = kernel_shape(lower_groups(MATERIALS[name].decomposition(), np.zeros((1, 4, 3))))
        for dtype in (np.float64, np.float32):
            module = kernels.cuda_module(shape, dtype)
            for kernel in ("mjed_cells", "mjed_force"):
                ptx, _ = cuda.compile_ptx(
                    getattr(module, kernel).py_func, signature(dtype), cc=(8, 0)
                )
                out["kernels"].append(
                    {
                        "material": name,
                        "kernel": kernel,
                        "dtype": np.dtype(dtype).name,
                        "f64": ptx.count(".f64"),
                        "f32": ptx.count(".f32"),
                        "atomics": ptx.count("atom."),
                        "entry": ".entry" in ptx,
                    }
                )
    from mjed.cuda import solvers

    i32, f64 = nt.int32[:], nt.float64[:]
    for fn, sig in (
        (kernels._zero, (nt.float64[:],)),
        (kernels._min_and_sum, (nt.float32[:], nt.float32[:], nt.float64[:])),
        (solvers._spmv, (i32, i32, f64, f64, f64)),
        (solvers._jacobi, (i32, i32, f64, f64)),
        (solvers._dots, (f64, f64, f64, f64)),
        (solvers._step, (f64, f64, f64, f64, f64, f64, nt.float64)),
        (solvers._direction, (f64, f64, nt.float64)),
        (solvers._residual_start, (f64, f64, f64, f64, f64)),
    ):
        ptx, _ = cuda.compile_ptx(fn.py_func, sig, cc=(8, 0))
        out["kernels"].append({"material": fn.py_func.__name__, "entry": ".entry" in ptx})
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])))
