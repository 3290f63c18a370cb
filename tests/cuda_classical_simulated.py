"""Run the classical element's CUDA kernels on Numba's CUDA simulator against the NumPy
classical element and print the errors as JSON (tests/test_cuda_classical.py runs this in a
subprocess: NUMBA_ENABLE_CUDASIM must be set before Numba is first imported).

    NUMBA_ENABLE_CUDASIM=1 python tests/cuda_classical_simulated.py [MATERIAL ...]
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np


def _rel_max(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / np.abs(b).max())


def main(names) -> dict:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    from conftest import MATERIALS, box_mesh, perturbed

    import mjed
    from mjed.cuda import simulated
    from reference_fem.classical import ClassicalGalerkin
    from reference_fem.classical_cuda import CudaClassicalGalerkin

    points, cells = box_mesh(1, jitter=0.0)  # 6 cells, 8 nodes: every node and edge shared
    mesh = mjed.TetMesh(points, cells)
    x = perturbed(points, np.random.default_rng(7), 0.05)
    out = {"simulated": simulated(), "cases": []}
    for name in names:
        ref = ClassicalGalerkin(mesh, None, MATERIALS[name])
        f_r, K_r = ref.force_and_stiffness(x)
        e_r = ref.energy(x)
        for dtype in ("float64", "float32"):
            gpu = CudaClassicalGalerkin(mesh, None, MATERIALS[name], dtype=np.dtype(dtype))
            f_g, K_g = gpu.force_and_stiffness(x)
            case = {
                "material": name,
                "dtype": dtype,
                "backend": gpu.backend,
                "force": _rel_max(f_g, f_r),
                "stiffness": _rel_max(K_g.toarray(), K_r.toarray()),
                "energy": abs(gpu.energy(x) - e_r) / abs(e_r),
                "force_alone": _rel_max(gpu.force(x), f_r),
            }
            if name == "NeoHookean":
                from numba import cuda

                e_d, f_d, data_d = gpu.device_force_and_stiffness(
                    cuda.to_device(np.asarray(x, dtype=dtype))
                )
                case["device_force"] = _rel_max(f_d.copy_to_host(), f_g)
                case["device_data"] = _rel_max(data_d.copy_to_host(), K_g.data)
            out["cases"].append(case)
    if "Costa" in names:  # one fibre frame per cell: Costa's tensor read per cell
        from scipy.spatial.transform import Rotation

        frame = Rotation.random(mesh.n_cells, random_state=3).as_matrix()
        costa = mjed.materials.Costa(
            a=0.9, k0=3.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5, frame=frame
        )
        gpu = CudaClassicalGalerkin(mesh, None, costa)
        f_r, K_r = ClassicalGalerkin(mesh, None, costa).force_and_stiffness(x)
        f_g, K_g = gpu.force_and_stiffness(x)
        out["costa_per_cell"] = {
            "per_cell_T": gpu.shape.per_cell_T,
            "force": _rel_max(f_g, f_r),
            "stiffness": _rel_max(K_g.toarray(), K_r.toarray()),
        }
    if "NeoHookean" in names:  # one launcher (device mesh arrays) shared by both fields
        from mjed.cuda import CudaForceField
        from mjed.cuda.launch import CellLauncher

        material = MATERIALS["NeoHookean"]
        shared = CellLauncher(mesh, np.float64)
        f_m = CudaForceField(mesh, material, launcher=shared).force(x)
        f_c = CudaClassicalGalerkin(mesh, None, material, launcher=shared).force(x)
        try:
            CudaClassicalGalerkin(mesh, None, material, dtype=np.float32, launcher=shared)
            refused = False
        except ValueError:
            refused = True
        out["shared_launcher"] = {
            "mjed": _rel_max(f_m, mjed.make_force_field(mesh, material).force(x)),
            "classical": _rel_max(f_c, ClassicalGalerkin(mesh, None, material).force(x)),
            "other_dtype_refused": refused,
        }
    # an inverted cell is refused, naming it (Neo-Hookean reads ln J: on the simulator
    # math.log raises for J < 0, so the cell is flattened to J = 0 exactly)
    if "NeoHookean" in names:
        z = mesh.points.copy()
        z[mesh.cells[2, 0]] = z[mesh.cells[2, 1:]].mean(axis=0)
        svk = MATERIALS["StVenantKirchhoff"]
        try:
            CudaClassicalGalerkin(mesh, None, svk).force(z)
            out["inverted"] = "not refused"
        except mjed.InvertedElementError as exc:
            out["inverted"] = str(exc)
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])))
