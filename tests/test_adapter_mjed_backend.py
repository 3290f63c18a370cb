"""MJED on each backend as an engine of the exchange format
(``python -m conformance.adapters.mjed_backend``), judged by ``mjed-verify check``: the NumPy
engine per case (``--command``), the compiled kernel filling a kit, and the cuda backend on
Numba's CUDA simulator in FP64 (passes at double precision) and FP32 (passes at single
precision, and fails at double precision as float32 round-off: FP32 really ran); and what the
adapter refuses, saying why.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from comparisons.cli import main
from conformance.adapters.mjed_backend import MJEDBackendEngine
from mjed.compiled import numba_available
from reference_fem import dolfinx_available

ROOT = Path(__file__).resolve().parents[1]
ADAPTER = [sys.executable, "-m", "conformance.adapters.mjed_backend"]
MATERIALS = "NeoHookean,Costa,Ogden"  # a plain one, one with a fibre frame, a spectral one
needs_dolfinx = pytest.mark.skipif(
    not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
)


def _env(**extra) -> dict:
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    return dict(os.environ, PYTHONPATH=path, **extra)


def _adapter(*args, **env):
    return subprocess.run(
        [*ADAPTER, *args], capture_output=True, text=True, env=_env(**env), cwd=ROOT, timeout=900
    )


def _export(kit: Path, *extra) -> None:
    argv = ["export", str(kit), "--material", MATERIALS, "--mesh", "single-tet"]
    assert main(argv + ["--states", "uniaxial,random", *extra]) == 0


def _check(kit, tmp_path, *extra) -> dict:
    """Exit code and cases of ``mjed-verify check`` (kit, or None with --command)."""
    out = tmp_path / "report"
    path = tmp_path / f"check{len(list(tmp_path.glob('check*.json')))}.json"
    argv = ["check"] + ([str(kit)] if kit else []) + [*extra, "--out", str(out)]
    code = main(argv + ["--json", str(path), "--quiet"])
    data = json.loads(path.read_text())
    return {"exit_code": code, "cases": data["cases"]}


@pytest.mark.oracle
@needs_dolfinx
def test_numpy_backend_per_case_passes_the_check(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PYTHONPATH", _env()["PYTHONPATH"])  # the engine imports this worktree
    command = " ".join(ADAPTER) + " {input} {output} --backend numpy"
    run = _check(
        None,
        tmp_path,
        "--command",
        command,
        "--material",
        "NeoHookean,Costa",
        "--mesh",
        "single-tet",
        "--states",
        "uniaxial",
    )
    assert run["exit_code"] == 0 and len(run["cases"]) == 2
    for c in run["cases"]:
        assert c["status"] == "passed" and c["tolerances"]["precision"] == "double"
        assert c["errors"]["force"] < 1e-13 and c["errors"]["stiffness"] < 1e-13


@pytest.mark.oracle
@needs_dolfinx
@pytest.mark.skipif(not numba_available(), reason="the numba backend needs Numba")
def test_numba_backend_fills_a_kit_that_passes(tmp_path):
    kit = tmp_path / "kit"
    _export(kit)
    ran = _adapter("--kit", str(kit), "--backend", "numba")
    assert ran.returncode == 0, ran.stderr
    assert "30 of 30 cases written by MJED (numba, float64)" in ran.stdout
    run = _check(kit, tmp_path)
    assert run["exit_code"] == 0 and len(run["cases"]) == 6
    assert all(c["status"] == "passed" for c in run["cases"])


def test_refusals_say_why(tmp_path):
    with pytest.raises(ValueError, match="float32 is the cuda backend's"):
        MJEDBackendEngine("numpy", "float32")
    with pytest.raises(ValueError, match="numpy, numba, cuda"):
        MJEDBackendEngine("opencl")
    ran = _adapter("in", "out", "--backend", "numba", "--dtype", "float32")
    assert ran.returncode == 2 and "not run" in ran.stderr and "float32" in ran.stderr
    ran = _adapter("in", "out", "--kit", str(tmp_path))
    assert ran.returncode == 2 and "not both" in ran.stderr
    # a user energy has no MJED decomposition: that case fails, named; the others are written
    kit = tmp_path / "energy"
    energy = ["--energy", "mu/2*(I1b-3) + K/2*(J-1)**2", "--param", "mu=1e3", "--param", "K=1e4"]
    assert main(["export", str(kit), "--mesh", "single-tet", "--states", "rest", *energy]) == 0
    ran = _adapter("--kit", str(kit))
    assert ran.returncode == 1 and "a user energy has no MJED decomposition" in ran.stderr
    assert "0 of 5 cases written" in ran.stdout


@pytest.mark.skipif(
    numba_available() and __import__("mjed.cuda", fromlist=["x"]).cuda_available(),
    reason="a CUDA device is present here",
)
def test_cuda_without_a_device_is_not_run_and_not_replaced(tmp_path):
    ran = subprocess.run(
        [*ADAPTER, "--kit", str(tmp_path), "--backend", "cuda"],
        capture_output=True,
        text=True,
        env={k: v for k, v in _env().items() if k != "NUMBA_ENABLE_CUDASIM"},
        cwd=ROOT,
        timeout=300,
    )
    assert ran.returncode == 2 and "mjed_backend: not run:" in ran.stderr and "cuda" in ran.stderr
    assert not list(tmp_path.iterdir())  # nothing written by a stand-in


@pytest.fixture(scope="module")
def simulated_kits(tmp_path_factory):
    """Kits filled by the cuda backend on the simulator, FP64 and FP32."""
    root = tmp_path_factory.mktemp("cuda_kits")
    out = {}
    for dtype, precision in (("float64", "double"), ("float32", "single")):
        kit = root / dtype
        _export(kit, "--precision", precision)
        ran = _adapter("--kit", str(kit), "--backend", "cuda", "--dtype", dtype, **_SIM)
        assert ran.returncode == 0, ran.stderr[-3000:]
        out[dtype] = (kit, ran.stdout)
    kit = root / "declared-double"
    _export(kit)
    out["refused"] = _adapter("--kit", str(kit), "--backend", "cuda", "--dtype", "float32", **_SIM)
    return out


_SIM = {"NUMBA_ENABLE_CUDASIM": "1"}
needs_numba = pytest.mark.skipif(not numba_available(), reason="the cuda backend needs Numba")


@pytest.mark.oracle
@needs_dolfinx
@needs_numba
def test_cuda_fp64_kit_passes_at_double_precision(simulated_kits, tmp_path):
    kit, said = simulated_kits["float64"]
    assert "30 of 30 cases written by MJED (cuda, float64)" in said
    assert not list(kit.glob("cases/*/output/*.f32"))
    run = _check(kit, tmp_path)
    assert run["exit_code"] == 0 and len(run["cases"]) == 6
    for c in run["cases"]:
        assert c["status"] == "passed" and c["tolerances"]["precision"] == "double", c["case"]
        assert max(c["errors"]["force"], c["errors"]["stiffness"]) < 1e-12


@pytest.mark.oracle
@needs_dolfinx
@needs_numba
def test_cuda_fp32_kit_passes_at_single_precision_only(simulated_kits, tmp_path):
    kit, said = simulated_kits["float32"]
    assert "30 of 30 cases written by MJED (cuda, float32)" in said
    assert len(list(kit.glob("cases/*/output/force.f32"))) == 30
    run = _check(kit, tmp_path)
    assert run["exit_code"] == 0 and len(run["cases"]) == 6
    for c in run["cases"]:
        assert c["status"] == "passed" and c["tolerances"]["precision"] == "single", c["case"]
        # float32 arithmetic really ran: errors of float32 round-off, not of float64
        assert 1e-10 < max(c["errors"]["force"], c["errors"]["stiffness"]) < 1e-5
    double = _check(kit, tmp_path, "--precision", "double")
    assert double["exit_code"] == 1
    for c in double["cases"]:
        assert c["status"] == "failed"
        assert any(f["code"] == "single-precision" for f in c["findings"]), c["findings"]


@needs_numba
def test_fp32_into_a_kit_declared_double_is_refused(simulated_kits):
    ran = simulated_kits["refused"]
    assert ran.returncode == 2 and "export the kit with --precision single" in ran.stderr
