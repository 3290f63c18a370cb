"""The generated CUDA kernels compile for a real GPU: PTX from libNVVM (the compiler behind
nvcc), for every material and both precisions, without a GPU. What Numba's simulator cannot
show (tests/test_cuda.py checks the arithmetic there). Skips, saying why, where no CUDA
toolkit's NVVM is found (set CUDA_HOME to one; PyPI's nvidia-cuda-nvcc-cu11 wheel, unpacked,
is enough: its libnvvm.so needs a versioned link, libnvvm.so.4, for Numba 0.56 to find it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import MATERIALS

from mjed.compiled import numba_available

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ptx():
    if not numba_available():
        pytest.skip("the cuda backend needs Numba")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]))
    env.setdefault("NUMBA_FORCE_CUDA_CC", "8.0")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    out = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "cuda_ptx.py"), *sorted(MATERIALS)],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=1200,
    )
    assert out.returncode == 0, out.stderr[-4000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if not result["nvvm"]:
        pytest.skip(f"no libNVVM (a CUDA toolkit) here: {result['reason']}")
    return result


def test_every_kernel_compiles_to_ptx(ptx):
    kernels = [k for k in ptx["kernels"] if "dtype" in k]
    # MJED and the classical element, cells and force kernels, FP64 and FP32
    assert len(kernels) == 8 * len(MATERIALS) and all(k["entry"] for k in ptx["kernels"])
    for k in kernels:
        if k["kernel"] in ("mjed_cells", "classical_cells"):
            # every block entry and force component, straight into memory
            assert k["atomics"] >= 144 + 12
        else:  # the force kernel has no stiffness code left
            assert 12 <= k["atomics"] < 144


def test_edge_kernel_compiles_with_the_force_its_only_atomics(ptx):
    # mjed.cuda.codegen.Assembly.EDGE: the six edge blocks stored, no atomic into the stiffness
    assert {k["dtype"] for k in ptx["edge_kernels"]} == {"float64", "float32"}
    for k in ptx["edge_kernels"]:
        assert k["entry"] and 12 <= k["atomics"] < 54, k
        if k["dtype"] == "float32":
            assert k["f64"] == 0 and k["f32"] > 0, k


def test_fp32_kernels_have_no_double_precision_instruction(ptx):
    # every literal and math call is rounded to float32: a double instruction would cost
    # 2x to 64x on GPUs (and mean the FP32 kernel is not single precision)
    for k in ptx["kernels"]:
        if k.get("dtype") == "float32":
            assert k["f64"] == 0 and k["f32"] > 0, k
