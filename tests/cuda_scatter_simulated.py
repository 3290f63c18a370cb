"""Run the element and edge assemblies of the cuda backend (mjed.cuda.codegen.Assembly.ELEMENT:
per-cell stiffness entries, then the gather kernel; EDGE: the six edge blocks per cell, then
their gather kernel) and the default atomic one on Numba's CUDA simulator against the NumPy
engine, and print the differences as JSON (tests/test_cuda_scatter.py
runs this in a subprocess: NUMBA_ENABLE_CUDASIM must be set before Numba is imported).

    NUMBA_ENABLE_CUDASIM=1 python tests/cuda_scatter_simulated.py [MATERIAL ...]
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
from cuda_support import max_relative


def _device_out(field, mesh, x, dtype: str):
    """(f, CSR values) of the device path with given outputs, as the benchmark calls it."""
    launcher = field.launcher
    x_d = launcher.to_device(x)
    out = (
        launcher.cuda.device_array((mesh.n_nodes, 3), dtype=dtype),
        launcher.cuda.device_array(field.pattern.nnz, dtype=dtype),
    )
    out[1].copy_to_device(np.full(field.pattern.nnz, 7.0, dtype=dtype))  # overwritten
    _, f_d, data_d = field.device_force_and_stiffness(x_d, out=out)
    return f_d.copy_to_host(), data_d.copy_to_host()


def _case(mesh, material, x, dtype: str) -> dict:
    import mjed
    from mjed.cuda import CudaForceField

    f_r, K_r = mjed.make_force_field(mesh, material).force_and_stiffness(x)
    atomic = CudaForceField(mesh, material, dtype=np.dtype(dtype))
    f_a, K_a = atomic.force_and_stiffness(x)
    out = {"material": material.name, "dtype": dtype}
    out["atomic_vs_numpy_K"] = max_relative(K_a.toarray(), K_r.toarray())
    for name in ("element", "edge"):
        field = CudaForceField(mesh, material, dtype=np.dtype(dtype), assembly=name)
        f_e, K_e = field.force_and_stiffness(x)
        f_d, data_d = _device_out(field, mesh, x, dtype)
        out.update(
            {
                f"{name}_vs_atomic_K": max_relative(K_e.data, K_a.data),
                f"{name}_vs_atomic_f": max_relative(f_e, f_a),
                f"{name}_vs_numpy_K": max_relative(K_e.toarray(), K_r.toarray()),
                f"{name}_vs_numpy_f": max_relative(f_e, f_r),
                f"{name}_same_pattern": bool(
                    np.array_equal(K_e.indptr, K_a.indptr)
                    and np.array_equal(K_e.indices, K_a.indices)
                ),
                f"{name}_device_out_K": max_relative(data_d, K_a.data),
                f"{name}_device_out_f": max_relative(f_d, f_a),
                f"{name}_force_alone": max_relative(field.force(x), f_a),
            }
        )
    return out


def main(names) -> dict:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    from conftest import MATERIALS, box_mesh, perturbed

    import mjed
    from mjed.cuda import simulated

    points, cells = box_mesh(1)  # 6 cells, 8 nodes: every node and edge shared
    mesh = mjed.TetMesh(points, cells)
    x = perturbed(points, np.random.default_rng(3), 0.05)
    cases = [_case(mesh, MATERIALS[n], x, d) for n in names for d in ("float64", "float32")]
    return {"simulated": simulated(), "cases": cases}


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:] or ["NeoHookean"])))
