"""The classical element on the GPU (reference_fem.classical_cuda): its generated CUDA
kernels on Numba's CUDA simulator against the NumPy classical element, for every material
of the test suite, FP64 and FP32; and the generator's CUDA target without Numba's CUDA.

The simulator runs the kernels as Python, one thread per cell, on a 6-cell mesh in which
every node and edge is shared (so the atomic adds into the force and the CSR values through
the block map are exercised); it needs NUMBA_ENABLE_CUDASIM=1 before Numba is imported, so
it runs in a subprocess (tests/cuda_classical_simulated.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import MATERIALS
from cuda_support import run_on_simulator

from mjed.compiled import numba_available

ROOT = Path(__file__).resolve().parents[1]
needs_numba = pytest.mark.skipif(
    not numba_available(),
    reason="the cuda backend needs Numba's CUDA target (Debian: python3-numba; PyPI: numba)",
)

#: FP64: round-off of sums of a few dozen terms. FP32: single precision's unit roundoff is
#: 6e-8 and the sums cancel; measured on the simulator: force 1.0e-6 to 1.5e-6, stiffness
#: 2.0e-7 to 4.1e-7, energy 6.3e-7 to 3.8e-6.
FP64_TOL = {"force": 1e-13, "stiffness": 1e-13, "energy": 1e-13}
FP32_TOL = {"force": 1e-5, "stiffness": 1e-5, "energy": 1e-5}


@pytest.fixture(scope="module")
def simulated():
    return run_on_simulator(
        [str(ROOT / "tests" / "cuda_classical_simulated.py"), *sorted(MATERIALS)]
    )


@needs_numba
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_classical_cuda_equals_numpy_classical_on_the_simulator(simulated, dtype):
    assert simulated["simulated"]
    tol = FP64_TOL if dtype == "float64" else FP32_TOL
    cases = [c for c in simulated["cases"] if c["dtype"] == dtype]
    assert sorted(c["material"] for c in cases) == sorted(MATERIALS)
    for c in cases:
        assert c["backend"] == "cuda"
        for q in ("force", "stiffness", "energy"):
            assert c[q] <= tol[q], (c["material"], q, c[q])
        assert c["force_alone"] <= tol["force"], c
    if dtype == "float32":  # single precision really ran (no silent promotion to double)
        assert max(c["force"] for c in cases) > 1e-9


@needs_numba
def test_classical_cuda_device_arrays_frames_and_inversion(simulated):
    neo = [c for c in simulated["cases"] if c["material"] == "NeoHookean"]
    assert len(neo) == 2
    for c in neo:  # the device-resident results are the host ones
        assert c["device_force"] == 0.0 and c["device_data"] == 0.0
    costa = simulated["costa_per_cell"]
    assert costa["per_cell_T"]
    assert costa["force"] <= FP64_TOL["force"] and costa["stiffness"] <= FP64_TOL["stiffness"]
    shared = simulated["shared_launcher"]  # MJED and classical fields on one launcher
    assert shared["mjed"] <= 1e-13 and shared["classical"] <= 1e-13
    assert shared["other_dtype_refused"]
    assert "cell 2" in simulated["inverted"] and "not refused" not in simulated["inverted"]


def test_classical_cuda_source_is_the_cpu_cell_body_with_device_exits():
    """The CUDA target changes only how a cell's results leave it: the same cell body, the
    force and blocks by atomic adds, no per-edge sums, and FP32 without a float64 literal.
    """
    from reference_fem.classical_codegen import (
        CUDA_SIGNATURE,
        ClassicalCudaTarget,
        LawShape,
        classical_source,
    )

    shape = LawShape("neohooke")
    cpu = classical_source(shape)
    gpu = classical_source(shape, ClassicalCudaTarget(np.float64))
    gpu32 = classical_source(shape, ClassicalCudaTarget(np.float32))
    for line in ("sb = 2.0 * (mu - lm * L)", "sa = lm * L - mu"):
        assert line in cpu and line in gpu
    assert f"def classical_cells({', '.join(CUDA_SIGNATURE)}):" in gpu
    assert "def classical_force(" in gpu and "want_stiffness = False" in gpu
    assert "U[ge" not in gpu and "Dg[" not in gpu and "force[n0, 0] -=" not in gpu
    # 144 atomic adds into the CSR values and 12 into the force, per kernel that has them
    kernel = gpu[gpu.index("def classical_cells(") : gpu.index("def classical_force(")]
    assert kernel.count("cuda.atomic.add(data,") == 144
    assert kernel.count("cuda.atomic.add(force,") == 12
    assert "f32(0.5)" in gpu32 and "f32_log(" in gpu32 and "math.log(J)" not in gpu32
