"""The hardware benchmark command (comparisons.hardware_bench): it runs end to end on a small
mesh, checks every backend's answer before timing it, and without a GPU prints "not run: no
GPU" for the GPU section instead of a figure.
"""

from __future__ import annotations

import json

import pytest

from mjed.compiled import numba_available

pytestmark = pytest.mark.skipif(
    not numba_available(), reason="the benchmark needs Numba (Debian: python3-numba; PyPI: numba)"
)


def test_benchmark_prints_cpu_figures_and_no_gpu_figure(tmp_path, capsys):
    from comparisons import hardware_bench
    from mjed.cuda import cuda_available

    out = tmp_path / "figures.json"
    assert hardware_bench.main(["--mesh", "cube-small", "--rounds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    figures = json.loads(out.read_text())
    cpu = figures["cpu"][0]
    assert cpu["material"] == "NeoHookean" and cpu["flops_per_cell"] > 0
    for name in (
        "numpy f+K",
        "numba-serial f+K",
        "numba-parallel f+K",
        "numba-parallel f",
        "numba-batched f+K",
        "numba-batched-parallel f+K",
    ):
        assert cpu["timings"][name]["ns_per_cell"] > 0 and name in text
    assert all(v > 0 for v in cpu["floors_ns_per_cell"].values())
    assert cpu["ratios"]["numba-serial / numba-batched, f+K"] > 0 and cpu["batch"] >= 1
    if not cuda_available():
        assert "GPU: not run: no GPU" in text and figures["gpu"] == {
            "status": hardware_bench.gpu_status()
        }


def test_gpu_section_code_path_runs_on_the_simulator():
    # The GPU section only runs on a device; its code path is exercised here on Numba's CUDA
    # simulator (figures meaningless, structure checked), in a subprocess (the simulator must
    # be chosen before Numba is imported).
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = (
        "import json; from comparisons.hardware_bench import gpu_figures; "
        "print(json.dumps(gpu_figures(sizes=(48,), repeats=1, copy_bytes=2**12)))"
    )
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(root))
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=root, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    fig = json.loads(out.stdout.strip().splitlines()[-1])
    row = fig["sizes"][0]
    assert row["cells"] == 48 and fig["copy_GBs"] > 0
    for key in ("float64 f", "float64 f+K", "float32 f", "float32 f+K"):
        assert row[key]["tets_per_s"] > 0 and row[key]["GBs"] > 0


def test_benchmark_never_times_the_simulator(monkeypatch):
    from comparisons import hardware_bench

    monkeypatch.setenv("NUMBA_ENABLE_CUDASIM", "1")
    assert "simulator" in hardware_bench.gpu_status()


def test_benchmark_refuses_an_unknown_material():
    from comparisons import hardware_bench

    with pytest.raises(SystemExit) as exc:
        hardware_bench.main(["--materials", "Rubber"])
    assert exc.value.code == 2
