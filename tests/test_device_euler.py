"""The implicit Euler step on the device (mjed.cuda.integrator.DeviceImplicitEuler) against
the host-built step (mjed.integrator.ImplicitEuler, its CG on the device too) with the same
cuda force field, on Numba's CUDA simulator (tests/device_euler_simulated.py, in a
subprocess): loads, Rayleigh damping, fixed and prescribed nodes, Newton, a consistent mass,
FP32 forces, substeps on failure and a step refused at every substep. And which integrator
:func:`mjed.cuda.integrator.implicit_euler` gives, and why the host one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mjed.compiled import numba_available

ROOT = Path(__file__).resolve().parents[1]

#: Both run the same equations in FP64 with CG to 1e-12; they differ in the order of the sums
#: (measured: 3.3e-16 on the positions after three steps).
TRAJECTORY_TOL = 1e-10

pytestmark = pytest.mark.skipif(
    not numba_available(), reason="the cuda backend needs Numba's CUDA target"
)


@pytest.fixture(scope="module")
def simulated():
    env = dict(
        os.environ,
        NUMBA_ENABLE_CUDASIM="1",
        PYTHONPATH=os.pathsep.join(
            [str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]
        ),
    )
    ran = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "device_euler_simulated.py")],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=1200,
    )
    assert ran.returncode == 0, ran.stderr[-4000:]
    return json.loads(ran.stdout.strip().splitlines()[-1])


def _same_steps(case):
    for key in ("time", "cg", "solves", "substeps", "retries"):
        device, host = case[key]
        assert device == host, (key, device, host)
    assert case["device_type"] == "DeviceImplicitEuler"
    assert case["host_calls"] == 0  # forces and stiffness never came to the host


@pytest.mark.parametrize("name", ["hyperelastic", "fp32", "prescribed_newton", "halving"])
def test_device_step_follows_the_host_step(simulated, name):
    case = simulated[name]
    _same_steps(case)
    assert case["peak"] > 1e-2  # the body moved: the comparison means something
    for key in ("x", "v", "reaction", "max_displacement"):
        assert case[key] <= TRAJECTORY_TOL, (name, key, case[key])


def test_newton_and_substeps_run_on_the_device(simulated):
    newton = simulated["prescribed_newton"]
    assert newton["solves"][0] == [4, 4]  # re-linearised until newton_tol
    device, host = newton["newton_residual"]
    assert all(d <= 1e-9 and h <= 1e-9 for d, h in zip(device, host))
    halving = simulated["halving"]
    assert halving["substeps"][0] == [1, 2] and halving["retries"][0][1] == ["volume_jump"]


def test_a_refused_step_fails_alike_and_keeps_the_state(simulated):
    failure = simulated["failure"]
    host, device = failure["host"], failure["device"]
    assert host["reason"] == device["reason"] == "inverted"
    assert device["message"] == host["message"]  # the same cells, J values and substeps named
    assert "retried in substeps" in device["message"]
    assert host["kept"] and device["kept"]
    assert failure["after"] <= TRAJECTORY_TOL  # and both go on alike from the kept state


def test_models_kept_on_the_host_fall_back_with_the_reason(simulated):
    chosen = simulated["fallback"]
    assert chosen["cuda"] == {"type": "DeviceImplicitEuler", "refusal": None}
    assert chosen["visco"]["type"] == "ImplicitEuler"
    assert "ViscoHyperelasticForceField updates a history" in chosen["visco"]["refusal"]
    assert chosen["host_cg"]["type"] == "ImplicitEuler"
    assert "'cg', not the device CG" in chosen["host_cg"]["refusal"]
    assert chosen["two_models"]["type"] == "ImplicitEuler"


def test_device_integrator_module_imports_without_numba():
    """mjed.cuda.integrator's refusal is usable where Numba is not (it imports Numba only when
    an integrator is built).
    """
    code = (
        "import sys; import mjed.cuda.integrator as m; "
        "from mjed.solvers import LinearSolverOptions as L; "
        "print('numba' in sys.modules, m.device_refusal([], L()))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "False"
