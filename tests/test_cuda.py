"""The cuda backend (mjed.cuda): its kernels on Numba's CUDA simulator against the NumPy
engine for every material, FP64 and FP32, both regularisation settings; and its host-side
parts (the CSR block map, the FP32 source rewrite, the backend choice) without Numba's CUDA.

The simulator runs the generated kernel as Python, one thread per cell, on a 6-cell mesh;
it needs NUMBA_ENABLE_CUDASIM=1 before Numba is imported, so it runs in a subprocess
(tests/cuda_simulated.py). It checks the arithmetic, the atomics into the force and the CSR
values and the block map; it cannot check that the CUDA compiler accepts the kernel or how
fast it is: that needs a GPU (docs/studies/timing.md, the GPU section).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import MATERIALS, box_mesh
from cuda_support import run_on_simulator

import mjed
from mjed.compiled import numba_available

ROOT = Path(__file__).resolve().parents[1]
needs_numba = pytest.mark.skipif(
    not numba_available(),
    reason="the cuda backend needs Numba's CUDA target (Debian: python3-numba; PyPI: numba, "
    "numba-cuda)",
)

#: FP32 tolerances: the single-precision unit roundoff is 6e-8; forces, stresses and energies
#: are sums in which terms of larger size cancel (the stored energy of a moderate state is a
#: small difference of f(J) g(C) terms), measured 1e-6 to 5e-6 on the simulator.
FP32_TOL = {"force": 5e-5, "stiffness": 5e-5, "stress": 5e-5, "energy": 1e-4}
FP64_TOL = {"force": 1e-13, "stiffness": 1e-13, "stress": 1e-13, "energy": 1e-12}


@pytest.fixture(scope="module")
def simulated():
    return run_on_simulator([str(ROOT / "tests" / "cuda_simulated.py"), *sorted(MATERIALS)])


@needs_numba
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_cuda_kernels_equal_numpy_engine_on_the_simulator(simulated, dtype):
    assert simulated["simulated"]
    tol = FP64_TOL if dtype == "float64" else FP32_TOL
    cases = [c for c in simulated["cases"] if c["dtype"] == dtype]
    assert {c["material"] for c in cases} == set(MATERIALS) and len(cases) == 2 * len(MATERIALS)
    for c in cases:
        assert c["backend"] == "cuda" and c["same_pattern"], c
        for q in ("force", "stiffness", "stress", "energy"):
            assert c[q] <= tol[q], (c["material"], c["regularize"], q, c[q])
        assert c["force_alone"] <= tol["force"] and c["stiffness_alone"] <= tol["stiffness"], c
    if dtype == "float32":  # single precision really ran (no silent promotion to double)
        assert max(c["force"] for c in cases) > 1e-9


@needs_numba
def test_cuda_device_arrays_inversion_and_regularisation(simulated):
    for c in simulated["cases"]:
        if c["material"] == "NeoHookean":
            assert (
                c["device_force"] == 0.0 and c["device_data"] == 0.0 and c["device_energy"] < 1e-6
            )
            if c["regularize"]:
                assert c["regularisation_changes_K"] > 1e-3  # the state has compressed cells
    assert "cell 2 " in simulated["inverted"]
    assert simulated["inverted_allowed"] < 1e-13  # allow_inverted evaluates, as the other backends


@needs_numba
def test_cuda_field_drives_the_implicit_integrator(simulated):
    # three backward Euler steps under gravity, forces and stiffness from the simulated kernel,
    # the linear systems solved on the host, then on the (simulated) device
    assert simulated["integrator"] < 1e-10
    assert (
        simulated["integrator_device_cg"] < 1e-9
        and simulated["integrator_device_cg_iterations"] > 0
    )


def test_cuda_cg_takes_the_jacobi_preconditioner_only():
    from mjed.solvers import LinearSolverOptions

    assert "GPU" in LinearSolverOptions(solver="cuda-cg").label()
    with pytest.raises(ValueError, match="cuda-cg.*jacobi"):
        LinearSolverOptions(solver="cuda-cg", preconditioner="factorized")


def test_block_map_points_at_each_blocks_entries():
    from mjed.cuda.codegen import block_map
    from mjed.sparse import CSRPattern

    points, cells = box_mesh(2, jitter=0.2)
    p = CSRPattern(cells, len(points))
    blk, rowlen = block_map(cells, p.indptr, p.indices, len(points))
    assert blk.shape == (len(cells), 16)
    rows = np.repeat(np.arange(p.shape[0]), np.diff(p.indptr))
    for e in (0, 7, len(cells) - 1):
        for a in range(4):
            for b in range(4):
                for r in range(3):
                    for c in range(3):
                        pos = blk[e, 4 * a + b] + r * rowlen[cells[e, a]] + c
                        assert (
                            rows[pos] == 3 * cells[e, a] + r
                            and p.indices[pos] == 3 * cells[e, b] + c
                        )


def test_fp32_source_rewrites_every_float_literal_and_math_call():
    from mjed.cuda.codegen import fp32_source

    code = "y = 2.0 * x_1 + 1e-17 * math.sqrt(J) - .5 + a2_0 * 3\nz = math.log(1.0 - q1)"
    assert fp32_source(code) == (
        "y = f32(2.0) * x_1 + f32(1e-17) * f32_sqrt(J) - f32(.5) + a2_0 * 3\nz = f32_log(f32(1.0) "
        "- q1)"
    )
    # a float64 constant in one branch of a conditional makes the whole expression float64
    assert fp32_source("i = 1.0 / a if a > 0.0 else math.nan") == (
        "i = f32(1.0) / a if a > f32(0.0) else f32(math.nan)"
    )
    assert fp32_source("b = -math.inf + math.infinity") == "b = -f32(math.inf) + math.infinity"


def test_generated_cuda_source_loops_over_the_cells_without_allocation():
    # what the simulator cannot catch: the CUDA target accepts no array allocation, no NumPy
    # call and no call to a CPU-compiled function inside a kernel
    from mjed.compiled.codegen import kernel_source
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape
    from mjed.cuda.codegen import CudaTarget

    for name in sorted(MATERIALS):  # Gent's log group once put a float64 NaN in FP32
        shape = kernel_shape(lower_groups(MATERIALS[name].decomposition(), np.zeros((1, 4, 3))))
        for dtype in (np.float64, np.float32):
            src = kernel_source(shape, CudaTarget(dtype))
            compile(src, "<cuda kernel>", "exec")
            assert "np." not in src and "local_" not in src and "njit" not in src
            loop = "for e in range(start, cells.shape[0], stride):"
            assert src.count("@cuda.jit(cache=True)") == 2 and src.count(loop) == 2
            force_kernel = src.split("def mjed_force")[1]
            assert "want_stiffness = False" in force_kernel.split(loop)[0]
            assert src.count("cuda.atomic.add(data") == 2 * 144
            if dtype == np.float32:
                body = src.split("def mjed_cells")[1]  # NaN and inf only as float32 constants
                assert "math." not in re.sub(r"f32\(math\.(nan|inf)\)", "", body)


@pytest.mark.skipif(
    numba_available() and __import__("mjed.cuda", fromlist=["cuda_available"]).cuda_available(),
    reason="a CUDA device (or the simulator) is present here",
)
def test_cuda_backend_without_a_device_says_why():
    points, cells = box_mesh(1)
    with pytest.raises(mjed.compiled.BackendUnavailable, match="cuda"):
        mjed.make_force_field(mjed.TetMesh(points, cells), MATERIALS["NeoHookean"], backend="cuda")


def test_unknown_backend_lists_cuda():
    points, cells = box_mesh(1)
    with pytest.raises(ValueError, match="numpy, numba, cuda"):
        mjed.make_force_field(
            mjed.TetMesh(points, cells), MATERIALS["NeoHookean"], backend="opencl"
        )


@needs_numba
def test_device_cg_solves_like_the_host_cg(simulated):
    cg = simulated["cg"]
    assert cg["converged"] and cg["residual"] <= 1e-12 and cg["difference"] < 1e-10
    assert abs(cg["iterations"] - cg["host_iterations"]) <= 1  # the same algorithm
    assert cg["warm_iterations"] == 0  # a converged first guess is returned as it is
    assert (
        cg["indefinite"] == cg["host_indefinite"] == "negative_curvature"
    )  # -A is refused as on the host


def _fp32_helpers() -> dict:
    """The device helpers (Jacobi eigen-decomposition, divided differences) as the FP32 CUDA
    module compiles them (their source through fp32_source), run as Python on NumPy float32
    scalars: every operation rounds to float32, as on a GPU (NumPy float32 with float32 stays
    float32 on every NumPy release).
    """
    import math

    from mjed.compiled.kernels import DEVICE_HELPERS
    from mjed.cuda.codegen import _helper_source, fp32_source

    ns = {"math": math, "f32": np.float32}
    for name in ("sqrt", "log", "exp", "expm1", "log1p"):
        ns[f"f32_{name}"] = lambda v, f=getattr(np, name): np.float32(f(np.float32(v)))
    for fn in DEVICE_HELPERS:
        exec(fp32_source(_helper_source(fn)), ns)
    return ns


@pytest.mark.parametrize("tiny", [1e-23, 3e-30])
def test_fp32_eigen_decomposition_of_two_equal_diagonal_entries_is_finite(tiny):
    # Seen on an H200 (FP32 Ogden kits at rest, in uniaxial stretch and compression: NaN
    # forces): with FMA the GPU's C has off-diagonals ~1e-8 where the simulator's is exactly
    # the identity; a rotation then leaves an entry ~1e-23 between two equal diagonal entries,
    # and b^2 underflowing to 0 gave rho = 0, c = 0 * inf = NaN.
    eigh = _fp32_helpers()["eigh3_sym"]
    f = np.float32
    with np.errstate(all="ignore"):  # a regression shows as NaN below, not as a warning
        r = eigh(f(1.0), f(1e-10), f(tiny), f(1.0), f(0.0), f(1.0))
    lam, V = np.array(r[:3], dtype=float), np.array(r[3:], dtype=float).reshape(3, 3)
    assert np.isfinite(lam).all() and np.isfinite(V).all(), r
    A = np.array([[1.0, 1e-10, tiny], [1e-10, 1.0, 0.0], [tiny, 0.0, 1.0]])
    assert np.allclose(np.sort(lam), np.linalg.eigvalsh(A), rtol=0, atol=1e-6)
    assert np.allclose(V.T @ V, np.eye(3), atol=1e-6)
