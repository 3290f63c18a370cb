"""The hardware benchmark command (comparisons.timing.hardware): it runs end to end on a small
mesh, checks every backend's answer before timing it, and without a GPU prints "not run: no
GPU" for the GPU section instead of a figure and judges no target; the GPU section
(comparisons.timing.gpu) runs on Numba's CUDA simulator on a tiny cube, every row present.
"""

from __future__ import annotations

import json

import pytest
from cuda_support import run_on_simulator

from mjed.compiled import numba_available

pytestmark = pytest.mark.skipif(
    not numba_available(), reason="the benchmark needs Numba (Debian: python3-numba; PyPI: numba)"
)


def test_benchmark_prints_cpu_figures_and_no_gpu_figure(tmp_path, capsys):
    from comparisons.timing import hardware as hardware_bench
    from mjed.cuda import cuda_available

    out = tmp_path / "figures.json"
    argv = ["--mesh", "cube-small", "--rounds", "1", "--json", str(out), "--gpu-sizes", "48"]
    assert hardware_bench.main(argv) == 0
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
        gpu = figures["gpu"]
        assert "GPU: not run: no GPU" in text and gpu["status"] == hardware_bench.gpu_status()
        assert gpu["sizes"] == [] and gpu["cpu"] is None
        # every target printed, none judged: never "met"
        assert len(gpu["targets"]) == 2 and all(t["met"] is None for t in gpu["targets"])
        assert text.count("target NeoHookean") == 2 and ": met" not in text
        assert "not run: no GPU" in text.split("target NeoHookean force only")[1]


def _simulated_section(sizes: str) -> dict:
    """The GPU section measured on Numba's CUDA simulator in a subprocess (it must be chosen
    before Numba is imported): its record as JSON and its printed text.
    """
    code = (
        "import json; from comparisons.timing.hardware import gpu_figures; "
        "from comparisons.timing.gpu import print_figures; "
        f"fig = gpu_figures(sizes=({sizes}), min_time=0.0, copy_bytes=2**12); "
        "lines = []; print_figures(fig, lines.append); "
        "print(json.dumps({'figures': fig.to_dict(), 'text': lines}))"
    )
    return run_on_simulator(["-c", code], timeout=900)


def test_gpu_section_code_path_runs_on_the_simulator():
    # The GPU section only runs on a device; its code path is exercised here on Numba's CUDA
    # simulator (figures meaningless, structure checked) on one tiny cube.
    from comparisons.timing.gpu import DTYPES, METHODS, QUANTITIES, GpuFigures

    run = _simulated_section("48,")
    fig = GpuFigures.from_dict(run["figures"])
    assert GpuFigures.from_dict(json.loads(json.dumps(fig.to_dict()))) == fig
    assert fig.measured and fig.simulated and fig.copy_GBs > 0
    assert len(fig.verification) == 4 and all(v.passed for v in fig.verification)
    (size,) = fig.sizes
    assert size.cells == 48 and not size.skipped
    for method in METHODS:
        for dtype in DTYPES:
            for q in QUANTITIES:
                t = size.timing(method, dtype, q)
                assert t is not None and t.tets_per_s > 0 and t.GBs > 0 and t.repeats >= 3
                assert any(line.lstrip().startswith(f"{method} ") and f"{dtype} {q} " in line
                           for line in run["text"])  # fmt: skip
    assert fig.cpu is not None and fig.cpu.cells == 48 and fig.cpu.force_vs_gpu <= 1e-12
    assert any("GPU / CPU, MJED FP64 f+K" in line for line in run["text"])
    # the simulator's figures never meet a target
    assert len(fig.targets) == 2 and all(t.met is None for t in fig.targets)
    assert sum("not judged: simulator" in line for line in run["text"]) == 2


def test_cube_counts_are_the_built_cube_s():
    from comparisons.timing.gpu import cube_counts
    from meshes.structured import cube_with_cells
    from mjed.sparse import CSRPattern

    for target in (48, 1_000, 10_000):
        points, cells = cube_with_cells(target)
        _, m, n, nnz = cube_counts(target)
        assert (m, n) == (len(cells), len(points))
        assert nnz == CSRPattern(cells, len(points)).nnz
    # the 1e7 cube: 10.1 M tets, its FP64 CSR values 1.84 GB
    _, m, n, nnz = cube_counts(10_000_000)
    assert m == 6 * 119**3 and nnz == 230_182_542


def test_a_size_that_does_not_fit_is_skipped_saying_why(monkeypatch):
    from comparisons.timing import gpu as gpu_bench

    monkeypatch.setattr(gpu_bench, "free_memory", lambda: 1e9)  # 1 GB free
    size, mesh, _ = gpu_bench.measure_size(10_000_000, None, set(), 1.0, 0.0)
    assert mesh is None and size.timings == () and len(size.skipped) == 2
    assert "float64: needs 3.95 GB" in size.skipped[0] and "1.00 GB free" in size.skipped[0]
    assert size.csr_bytes["float64"] == 8 * size.nnz


def test_targets_are_judged_on_their_figures_and_never_on_the_simulator():
    from comparisons.timing.gpu import TARGETS, GpuSize, GpuTiming, judge

    def size(cells, tets_per_s):
        timings = tuple(
            GpuTiming("mjed", "float64", q, 1.0, 1.0, 3, tets_per_s, 1, 1.0, 0.5)
            for q in ("f", "f+K")
        )
        return GpuSize(cells, cells, 1, 1, {}, {}, 0.0, timings)

    fast, slow = [size(998_250, 5e9)], [size(998_250, 2e9)]
    assert [t.met for t in judge(fast, "NeoHookean", False)] == [True, True]
    assert [t.met for t in judge(slow, "NeoHookean", False)] == [True, False]
    assert "missed (2.000e+09" in judge(slow, "NeoHookean", False)[1].line()
    assert [t.met for t in judge(fast, "NeoHookean", True)] == [None, None]
    assert [t.met for t in judge([size(100_000, 5e9)], "NeoHookean", False)] == [None, None]
    assert [t.met for t in judge(fast, "Ogden", False)] == [None, None]
    assert len(TARGETS) == 2


def test_benchmark_never_times_the_simulator(monkeypatch):
    from comparisons.timing import hardware as hardware_bench

    monkeypatch.setenv("NUMBA_ENABLE_CUDASIM", "1")
    assert "simulator" in hardware_bench.gpu_status()


def test_benchmark_refuses_an_unknown_material():
    from comparisons.timing import hardware as hardware_bench

    with pytest.raises(SystemExit) as exc:
        hardware_bench.main(["--materials", "Rubber"])
    assert exc.value.code == 2
