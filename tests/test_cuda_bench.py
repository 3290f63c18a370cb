"""The hardware benchmark command (comparisons.hardware_bench): it runs end to end on a small
mesh, checks every backend's answer before timing it, and without a GPU prints "not run: no
GPU" for the GPU section instead of a figure."""

from __future__ import annotations

import json

import pytest

from mjed.compiled import numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="the benchmark needs Numba "
                                "(Debian: python3-numba; PyPI: numba)")


def test_benchmark_prints_cpu_figures_and_no_gpu_figure(tmp_path, capsys):
    from comparisons import hardware_bench
    from mjed.cuda import cuda_available

    out = tmp_path / "figures.json"
    assert hardware_bench.main(["--mesh", "cube-small", "--rounds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    figures = json.loads(out.read_text())
    cpu = figures["cpu"][0]
    assert cpu["material"] == "NeoHookean" and cpu["flops_per_cell"] > 0
    for name in ("numpy f+K", "numba-serial f+K", "numba-parallel f+K", "numba-parallel f"):
        assert cpu["timings"][name]["ns_per_cell"] > 0 and name in text
    assert all(v > 0 for v in cpu["floors_ns_per_cell"].values())
    if not cuda_available():
        assert "GPU: not run: no GPU" in text and figures["gpu"] == {"status": hardware_bench.gpu_status()}


def test_benchmark_never_times_the_simulator(monkeypatch):
    from comparisons import hardware_bench

    monkeypatch.setenv("NUMBA_ENABLE_CUDASIM", "1")
    assert "simulator" in hardware_bench.gpu_status()


def test_benchmark_refuses_an_unknown_material():
    from comparisons import hardware_bench

    with pytest.raises(SystemExit) as exc:
        hardware_bench.main(["--materials", "Rubber"])
    assert exc.value.code == 2
