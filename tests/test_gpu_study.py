"""The report's GPU section (comparisons.timing.gpu_section): the hardware benchmark's GPU figures
when a JSON of them is present, "not run: no GPU" otherwise; a target is judged only on a device's
figures, never on a run without one or on the simulator.
"""

from __future__ import annotations

import json

from common.result import Status
from comparisons.timing.gpu import GpuFigures, GpuSize, GpuTiming, Verification, judge, not_run
from comparisons.timing.gpu_section import KEY, gpu_study


def _figures(tets_per_s: float, simulated: bool = False) -> GpuFigures:
    """A record shaped as a device run writes it (the figures are made up for the test)."""
    timings = tuple(
        GpuTiming(m, d, q, 1e-3, 1.1e-3, 10, tets_per_s, 10**9, 1000.0, 0.4)
        for m in ("mjed", "classical")
        for d in ("float64", "float32")
        for q in ("f", "f+K")
    )
    sizes = (GpuSize(1_000_000, 998_250, 175_616, 23_036_814, {}, {}, 2.0, timings),)
    checks = (Verification("mjed", "float64", 10_368, 1e-16, 2e-16, 1e-10),)
    return GpuFigures(
        "measured", "NeoHookean", "NVIDIA H100 80GB HBM3", "2026-12-01 10:00 UTC", simulated,
        2500.0, 7e10, checks, sizes, None, judge(sizes, "NeoHookean", simulated), 200.0,
    )  # fmt: skip


def test_without_figures_the_section_is_not_run_no_gpu(tmp_path):
    r = gpu_study(tmp_path / "absent.json")
    assert r.key == KEY and r.status is Status.NOT_RUN
    assert r.headline.startswith("not run: no GPU") and not r.checks


def test_a_run_without_a_device_or_on_the_simulator_is_not_run_no_gpu(tmp_path):
    for fig in (not_run("not run: no GPU (numba.cuda found no CUDA device)"), _figures(5e9, True)):
        path = tmp_path / "gpu.json"
        path.write_text(json.dumps({"cpu": [], "gpu": fig.to_dict()}))  # hardware_bench --json
        r = gpu_study(path)
        assert r.status is Status.NOT_RUN and r.headline.startswith("not run: no GPU")
        assert not any(c.passed for c in r.checks)


def test_a_device_run_is_shown_with_its_targets_judged(tmp_path):
    path = tmp_path / "gpu.json"
    path.write_text(json.dumps(_figures(5e9).to_dict()))  # a bare section is read too
    r = gpu_study(path)
    assert r.status is Status.PASSED and "NVIDIA H100" in r.headline
    targets = [c for c in r.checks if c.kind == "target"]
    assert len(targets) == 2 and all(c.passed for c in targets)
    table = r.blocks[1]
    assert len(table.rows) == 8 and table.rows[0][:4] == ["998,250", "mjed", "float64", "f"]
    assert "not measured by this run" in r.blocks[0].text and "2026-12-01" in r.blocks[0].text
    assert GpuFigures.from_dict(json.loads(json.dumps(r.data))) == _figures(5e9)

    path.write_text(json.dumps(_figures(2e9).to_dict()))  # force+stiffness met, force missed
    r = gpu_study(path)
    assert r.status is Status.TARGET_MISSED
    assert [c.passed for c in r.checks if c.kind == "target"] == [True, False]


def test_the_report_has_the_gpu_section():
    from comparisons.report.studies import study_keys

    assert KEY in study_keys()
