"""Run the cuda backend on Numba's CUDA simulator against the NumPy engine and print the
errors as JSON (tests/test_cuda.py runs this in a subprocess: NUMBA_ENABLE_CUDASIM must be
set before Numba is first imported, which a pytest process may already have done).

    NUMBA_ENABLE_CUDASIM=1 python tests/cuda_simulated.py [MATERIAL ...]
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

    points, cells = box_mesh(
        1, jitter=0.0
    )  # 6 cells, 8 nodes: every node shared, every edge shared
    mesh = mjed.TetMesh(points, cells)
    x = perturbed(points, np.random.default_rng(7), 0.05)
    x_c = mesh.points + 0.6 * (x - mesh.points)
    x_c[:, 2] *= 0.85  # compressed cells (J < 1), where the regularisation changes the tangent
    out = {"simulated": simulated(), "cases": []}
    for name in names:
        for dtype in ("float64", "float32"):
            for regularize in (False, True):
                y = x_c if regularize else x
                ref = mjed.make_force_field(mesh, MATERIALS[name], regularize=regularize)
                gpu = mjed.make_force_field(
                    mesh,
                    MATERIALS[name],
                    backend="cuda",
                    regularize=regularize,
                    dtype=np.dtype(dtype),
                )
                f_r, K_r = ref.force_and_stiffness(y)
                f_g, K_g = gpu.force_and_stiffness(y)
                case = {
                    "material": name,
                    "dtype": dtype,
                    "regularize": regularize,
                    "backend": gpu.backend,
                    "force": _rel_max(f_g, f_r),
                    "stiffness": _rel_max(K_g.toarray(), K_r.toarray()),
                    "same_pattern": bool(
                        np.array_equal(K_g.indptr, K_r.indptr)
                        and np.array_equal(K_g.indices, K_r.indices)
                    ),
                    "energy": abs(gpu.energy(y) - ref.energy(y)) / abs(ref.energy(y)),
                    "stress": _rel_max(gpu.stress(y), ref.stress(y)),
                    "force_alone": _rel_max(gpu.force(y), f_r),
                    "stiffness_alone": _rel_max(gpu.stiffness(y).toarray(), K_r.toarray()),
                }
                if name == "NeoHookean":
                    from numba import cuda

                    e_d, f_d, data_d = gpu.device_force_and_stiffness(
                        cuda.to_device(np.asarray(y, dtype=dtype))
                    )
                    case["device_force"] = _rel_max(f_d.copy_to_host(), f_g)
                    case["device_data"] = _rel_max(data_d.copy_to_host(), K_g.data)
                    case["device_energy"] = abs(e_d - gpu.energy(y)) / abs(gpu.energy(y))
                    if regularize:
                        K0 = mjed.make_force_field(
                            mesh, MATERIALS[name], backend="cuda", dtype=np.dtype(dtype)
                        )
                        case["regularisation_changes_K"] = _rel_max(
                            K0.stiffness(y).toarray(), K_g.toarray()
                        )
                out["cases"].append(case)
    # An inverted cell is refused, naming it, unless allowed. St Venant-Kirchhoff: the
    # simulator runs math.log as Python, which raises for J < 0 where a device returns NaN.
    z = mesh.points.copy()
    z[mesh.cells[2, 0]] = z[mesh.cells[2, 1:]].mean(axis=0) * 2 - z[mesh.cells[2, 0]]
    svk = MATERIALS["StVenantKirchhoff"]
    try:
        mjed.make_force_field(mesh, svk, backend="cuda").force(z)
        out["inverted"] = "not refused"
    except mjed.InvertedElementError as exc:
        out["inverted"] = str(exc)
    loose = mjed.make_force_field(mesh, svk, backend="cuda", allow_inverted=True).force(z)
    out["inverted_allowed"] = _rel_max(
        loose, mjed.make_force_field(mesh, svk, allow_inverted=True).force(z)
    )
    # The cuda field as a force model of the implicit integrator (forces and stiffness on the
    # device, the CG on the host): same trajectory as the NumPy engine's, FP64.
    from mjed.integrator import ImplicitEuler
    from mjed.solvers import LinearSolverOptions

    fixed = np.flatnonzero(mesh.points[:, 2] == 0.0)
    positions = {}
    for backend, solver in (("numpy", "cg"), ("cuda", "cg"), ("cuda", "cuda-cg")):
        field = mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend=backend)
        integ = ImplicitEuler(
            mesh,
            field,
            1.0,
            dt=0.05,
            fixed_nodes=fixed,
            solver=LinearSolverOptions(solver=solver, cg_tol=1e-12),
        )
        reports = integ.run(3)
        positions[backend, solver] = integ.x
    ref = positions["numpy", "cg"] - mesh.points
    out["integrator"] = _rel_max(positions["cuda", "cg"] - mesh.points, ref)
    out["integrator_device_cg"] = _rel_max(positions["cuda", "cuda-cg"] - mesh.points, ref)
    out["integrator_device_cg_iterations"] = int(sum(r.cg_iterations for r in reports))

    # CG on the device against the host CG, on a system like an implicit step's (K + c I)
    import scipy.sparse as sp

    from mjed.cuda.solvers import DeviceCSR, device_conjugate_gradient
    from mjed.solvers import conjugate_gradient

    K = mjed.make_force_field(mesh, MATERIALS["NeoHookean"]).stiffness(x)
    A = (K + 0.05 * abs(K).max() * sp.identity(K.shape[0], format="csr")).tocsr()
    A.sort_indices()
    rhs = np.random.default_rng(3).standard_normal(A.shape[0])
    host = conjugate_gradient(A, rhs, tol=1e-12, max_iterations=500)
    dev = device_conjugate_gradient(A, rhs, tol=1e-12, max_iterations=500)
    from numba import cuda

    on_device = DeviceCSR(
        A.indptr, A.indices, cuda.to_device(A.data)
    )  # values already on the device
    dev2 = device_conjugate_gradient(on_device, rhs, tol=1e-12, x0=host.x)
    indefinite = device_conjugate_gradient(-A, rhs, tol=1e-12)
    out["cg"] = {
        "converged": dev.converged,
        "iterations": dev.iterations,
        "host_iterations": host.iterations,
        "residual": float(np.linalg.norm(rhs - A @ dev.x) / np.linalg.norm(rhs)),
        "difference": _rel_max(dev.x, host.x),
        "warm_iterations": dev2.iterations,
        "indefinite": indefinite.reason,
        "host_indefinite": conjugate_gradient(-A, rhs, tol=1e-12).reason,
    }
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])))
