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

    def signature(dtype, table, per_cell_data=False):
        """The kernel's argument types as CudaForceField launches it (CellLauncher.launch):
        the material's numbers typed from its lowered table, so a change of their layout
        (group_coef became 2-D with Yeoh and Gent) cannot leave this list behind.
        """
        f = nt.float64 if dtype == np.float64 else nt.float32
        a = lambda t, nd: nt.Array(t, nd, "C")  # noqa: E731
        i = nt.int32
        numbers = tuple(
            a(f, np.ndim(v))
            for v in (table.jpar, table.gpar, table.gmat, table.group_coef, table.slot_M)
        )
        head = (a(f, 2), a(i, 2), a(f, 3), a(f, 1))  # x, cells, D, V0
        flags = (nt.boolean,) * 4  # regularize, want force, stiffness, stress
        data = a(f, 2) if per_cell_data else a(f, 1)  # (54, m) for the edge assembly
        tail = (a(i, 2), a(i, 1), a(f, 2), data, a(f, 1), a(f, 1), a(f, 3))
        return head + numbers + flags + tail

    out = {"nvvm": True, "kernels": [], "edge_kernels": []}
    for name in names:
        table = lower_groups(MATERIALS[name].decomposition(), np.zeros((1, 4, 3)))
        shape = kernel_shape(table)
        for dtype in (np.float64, np.float32):
            module = kernels.cuda_module(shape, dtype)
            for kernel in ("mjed_cells", "mjed_force"):
                ptx, _ = cuda.compile_ptx(
                    getattr(module, kernel).py_func, signature(dtype, table), cc=(8, 0)
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
    for name in names[:1]:  # the edge assembly's cell kernel (mjed.cuda.codegen.Assembly.EDGE)
        table = lower_groups(MATERIALS[name].decomposition(), np.zeros((1, 4, 3)))
        for dtype in (np.float64, np.float32):
            module = kernels.cuda_module(kernel_shape(table), dtype, "edge")
            ptx, _ = cuda.compile_ptx(
                module.mjed_cells.py_func, signature(dtype, table, True), cc=(8, 0)
            )
            out["edge_kernels"].append(
                {
                    "material": name,
                    "dtype": np.dtype(dtype).name,
                    "f64": ptx.count(".f64"),
                    "f32": ptx.count(".f32"),
                    "atomics": ptx.count("atom."),
                    "entry": ".entry" in ptx,
                }
            )
    out["kernels"] += classical_kernels(names)
    from mjed.cuda import solvers, step_kernels

    i32, f64, f32 = nt.int32[:], nt.float64[:], nt.float32[:]
    for fn, sig in (
        (kernels.gather_blocks, (f64, i32, i32, i32, i32, nt.int64, f64)),
        (kernels.gather_blocks, (f32, i32, i32, i32, i32, nt.int64, f32)),
        (kernels.gather_edge_blocks, (f64, i32, i32, i32, i32, i32, nt.int64, f64)),
        (kernels.gather_edge_blocks, (f32, i32, i32, i32, i32, i32, nt.int64, f32)),
        (step_kernels.fill_zero, (nt.float64[:],)),
        (step_kernels.clear, (nt.float64[:],)),
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


def classical_kernels(names) -> list:
    """The classical element's CUDA kernels (reference_fem.classical_cuda), as the MJED ones."""
    from conftest import MATERIALS
    from numba import cuda
    from numba import types as nt

    from mjed.compiled.specialise import generated_module
    from reference_fem import classical_materials as cm
    from reference_fem.classical_codegen import ClassicalCudaTarget, classical_source
    from reference_fem.classical_compiled import lower_law

    out = []
    for name in names:
        shape, params, tensor = lower_law(cm.classical_law(MATERIALS[name]))
        for dtype in (np.float64, np.float32):
            f = nt.float64 if dtype == np.float64 else nt.float32
            a = lambda t, nd: nt.Array(t, nd, "C")  # noqa: E731
            i = nt.int32
            signature = (
                (a(f, 2), a(i, 2), a(f, 3), a(f, 1))  # x, cells, D, V0
                + (a(f, np.ndim(params)), a(f, np.ndim(tensor)))
                + (nt.boolean, nt.boolean)  # want force, stiffness
                + (a(i, 2), a(i, 1), a(f, 2), a(f, 1), a(f, 1), a(f, 1))
            )
            target = ClassicalCudaTarget(np.dtype(dtype))
            module = generated_module(
                classical_source(shape, target), f"classical_cuda_{np.dtype(dtype).name}"
            )
            for kernel in ("classical_cells", "classical_force"):
                ptx, _ = cuda.compile_ptx(getattr(module, kernel).py_func, signature, cc=(8, 0))
                out.append(
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
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])))
