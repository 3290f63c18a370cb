"""The liver study on the GPU backends (``--backends cuda``, ``cuda-fp32``): without a device
they are left out saying "not run: no GPU", never replaced by another backend; on Numba's CUDA
simulator (tests/liver_cuda_simulated.py, in a subprocess) the study runs end to end with the
force field and the implicit Euler solve on the (simulated) device, and follows the NumPy
run's trajectory (the hyperelastic step entirely on the device: mjed.cuda.integrator).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cuda_support import run_on_simulator

from comparisons.cli import main
from comparisons.liver.setup import (
    KNOWN_BACKENDS,
    LIVER_SOLVER,
    LiverParameters,
    backend_force_field,
    run_solver,
)
from comparisons.liver.study import BACKEND_AGREEMENT_TOL, MODELS, liver_study
from meshes.structured import structured_box
from mjed.compiled import numba_available

ROOT = Path(__file__).resolve().parents[1]

#: FP64 on the device against the NumPy engine, every solve to 1e-12: the forces differ by
#: round-off (1e-13, tests/test_cuda.py), measured 2.3e-13 over three steps.
FP64_TRAJECTORY_TOL = 1e-10
#: FP32: forces and stiffness off by float32 round-off (1e-6 to 5e-6), measured 5.9e-7.
FP32_TRAJECTORY_TOL = 1e-5


def _no_device() -> bool:
    if not numba_available():
        return True
    from mjed.cuda import cuda_available

    return not cuda_available()


def test_gpu_backends_take_the_device_cg_with_the_study_tolerances():
    assert {"cuda", "cuda-fp32"} <= set(KNOWN_BACKENDS)
    params = LiverParameters()
    for name in ("cuda", "cuda-fp32"):
        solver = run_solver(backend_force_field(name), params)
        assert solver.solver == "cuda-cg" and solver.preconditioner == "jacobi"
        assert (solver.cg_tol, solver.max_iterations) == (
            LIVER_SOLVER.cg_tol,
            LIVER_SOLVER.max_iterations,
        )
    assert run_solver(backend_force_field("numpy"), params) == params.solver
    assert run_solver(lambda *a, **k: None, params) == params.solver  # a factory from Python


@pytest.mark.skipif(not _no_device(), reason="a CUDA device (or the simulator) is present")
def test_gpu_backend_without_a_device_is_left_out_saying_why(tmp_path, capsys):
    points, cells = structured_box(1, (0.1, 0.1, 0.1))
    res = liver_study(
        mesh=(points, cells),
        fixed=["box:-1,-1,0.099,1,1,1"],
        steps=1,
        models=["hyperelastic"],
        backends=["numpy", "cuda", "cuda-fp32"],
        oscillation=False,
        series=False,
        out_dir=str(tmp_path),
    )
    assert [r["backend"] for r in res.data["runs"]] == ["numpy"]  # no silent stand-in
    assert res.partial
    for name in ("cuda", "cuda-fp32"):
        assert any(f"the {name} backend: not run: no GPU" in n for n in res.not_covered)
    # the GPU alone: nothing can run, bad input (2) naming why
    code = main(["liver", "--quick", "--backends", "cuda", "--out", str(tmp_path / "alone")])
    err = capsys.readouterr().err
    assert code == 2 and "not run: no GPU" in err
    assert main(["liver", "--quick", "--backends", "cuda,opencl", "--out", str(tmp_path)]) == 2
    assert "cuda-fp32" in capsys.readouterr().err  # the known backends are listed


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("liver_cuda")
    return run_on_simulator([str(ROOT / "tests" / "liver_cuda_simulated.py"), str(out)])


needs_numba = pytest.mark.skipif(
    not numba_available(), reason="the cuda backend needs Numba's CUDA target"
)


@needs_numba
def test_liver_command_runs_every_model_on_the_simulated_gpu(simulated):
    run = simulated["command"]
    # every run completes; the FPS of the simulator miss the targets (3), and say why
    assert run["exit_code"] == 3 and run["status"] == "target missed"
    backends = ["numpy", "cuda", "cuda-fp32"]
    assert [(r["backend"], r["model"]) for r in run["runs"]] == [
        (b, m) for b in backends for m in MODELS
    ]
    for r in run["runs"]:
        assert r["error"] is None and r["steps"] == r["steps_planned"]
        gpu = r["backend"] != "numpy"
        assert ("CG on the GPU" in r["solver"]) == gpu
        assert ("CUDA simulator (not a GPU" in r["force_field"]) == gpu
        # every model's step on the device, the viscous history and the fluid pressure included
        # (mjed.cuda.device_models), saying so
        assert ("; step on the device" in r["solver"]) == gpu, r["solver"]
        assert "step built on the host" not in r["solver"]
    assert "FP32" in run["runs"][-1]["force_field"]
    agreement = run["agreement"]
    assert len(agreement) == 2 * len(MODELS)
    assert all(0 <= a["relative_difference"] <= BACKEND_AGREEMENT_TOL for a in agreement)
    printed = run["printed"]
    assert "cuda-fp32" in printed and "CG on the GPU, jacobi preconditioner" in printed


@needs_numba
def test_gpu_trajectories_follow_the_numpy_engine(simulated):
    tight = simulated["tight"]
    assert [r["backend"] for r in tight["runs"]] == ["numpy", "cuda", "cuda-fp32"]
    assert all("step on the device" in r["solver"] for r in tight["runs"][1:])
    assert all(r["steps"] == 3 and r["error"] is None for r in tight["runs"])
    assert min(tight["peak"]) > 1e-3  # the box sags by millimetres: the comparison means something
    diff = {a["backend"]: a["relative_difference"] for a in tight["agreement"]}
    assert diff["cuda"] <= FP64_TRAJECTORY_TOL
    assert diff["cuda-fp32"] <= FP32_TRAJECTORY_TOL
    # single precision really ran: its trajectory is off by float32 round-off, not 1e-13
    assert diff["cuda-fp32"] > 100 * diff["cuda"]
    assert np.isclose(tight["peak"][1], tight["peak"][0], rtol=FP64_TRAJECTORY_TOL)


def test_a_step_is_timed_until_the_device_is_done():
    """The step's clock stops after the factory's ``synchronize`` (the GPU's, which waits for
    the device's kernels and copies) has returned: its time is in the FPS.
    """
    import time

    from comparisons.liver.simulation import simulate
    from mjed import TetMesh

    calls = []

    def synchronize():
        time.sleep(0.05)  # a device still busy with the step
        calls.append(1)

    numpy_field = backend_force_field("numpy")

    def factory(mesh, material, **options):
        return numpy_field(mesh, material, **options)

    factory.backend, factory.label, factory.synchronize = "slow-device", "test", synchronize
    points, cells = structured_box(1, (0.1, 0.1, 0.1))
    fixed = np.flatnonzero(points[:, 2] > 0.099)
    run = simulate(
        "hyperelastic", TetMesh(points, cells), LiverParameters(), fixed, 0.6, force_field=factory
    )
    assert run.steps == 2 and len(calls) == 2
    assert run.stepping_seconds >= 0.1 and run.fps <= 20.0
