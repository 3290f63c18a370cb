"""comparisons.timing.gpu_occupancy: the occupancy arithmetic by hand, its limits checked, and
the command's refusal where no real device can report registers (reading them needs a GPU).
"""

from __future__ import annotations

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest
from cuda_support import ROOT

from comparisons.timing.gpu_occupancy import (
    FORMS,
    OccupancyLimits,
    device_limits,
    read_kernels,
    theoretical_occupancy,
)
from comparisons.timing.gpu_occupancy import (
    main as gpu_occupancy_main,
)

#: An H100/H200 SM (compute capability 9.0): 65,536 registers, 2,048 threads = 64 warps,
#: 32 blocks, registers per warp allocated by 256.
SM90 = OccupancyLimits(
    warp_size=32,
    max_threads_per_sm=2048,
    max_blocks_per_sm=32,
    regs_per_sm=65536,
    max_regs_per_block=65536,
    max_regs_per_thread=255,
    register_unit=256,
    max_threads_per_block=1024,
)


@pytest.mark.parametrize(
    "regs, threads, expected",
    [
        # 255 regs: 255 * 32 = 8,160 per warp, rounded up to 256s: 8,192; 65,536 / 8,192 =
        # 8 warps; 128 threads = 4 warps a block: 2 blocks, 8 warps of 64 = 12.5 %
        (255, 128, (2, 8, 0.125)),
        # 64 regs: 2,048 per warp, 32 warps = 8 blocks of 4: 32 / 64 = 50 %
        (64, 128, (8, 32, 0.5)),
        # 32 regs: 1,024 per warp, 64 warps = 16 blocks; 2,048 threads allow 16 too: 100 %
        (32, 128, (16, 64, 1.0)),
        # 41 regs: 1,312 per warp, rounded up to 1,536 (6 units); 65,536 // 1,536 = 42 warps,
        # 42 // 4 = 10 blocks, 40 warps: 62.5 % (without the rounding: 49 warps, 75 %)
        (41, 128, (10, 40, 0.625)),
        # 16 regs, one-warp blocks: registers allow 128 blocks, threads 64, the SM 32 blocks
        (16, 32, (32, 32, 0.5)),
        # 100 threads take 4 whole warps: as 128 threads at 64 regs
        (64, 100, (8, 32, 0.5)),
        # 255 regs at 1,024 threads: 32 warps * 8,192 = 262,144 registers > 65,536 a block
        (255, 1024, (0, 0, 0.0)),
    ],
)
def test_occupancy_by_hand(regs, threads, expected):
    assert theoretical_occupancy(regs, threads, SM90) == expected


@pytest.mark.parametrize("regs, threads", [(0, 128), (256, 128), (32, 0), (32, 1025)])
def test_counts_out_of_range_are_refused(regs, threads):
    with pytest.raises(ValueError):
        theoretical_occupancy(regs, threads, SM90)


@pytest.mark.parametrize(
    "change",
    [
        {"warp_size": 0},
        {"regs_per_sm": -65536},
        {"register_unit": 256.0},
        {"max_blocks_per_sm": True},
        {"max_threads_per_sm": 2000},  # not a whole number of 32-thread warps
        {"max_threads_per_block": 4096},  # more than an SM holds
        {"max_regs_per_block": 131072},  # more than the SM has
    ],
)
def test_invalid_limits_are_refused(change):
    with pytest.raises(ValueError):
        OccupancyLimits(**{**SM90.__dict__, **change})


def test_limits_are_read_from_the_device_attributes():
    device = SimpleNamespace(
        WARP_SIZE=32,
        MAX_THREADS_PER_MULTIPROCESSOR=1536,
        MAX_BLOCKS_PER_MULTIPROCESSOR=16,
        MAX_REGISTERS_PER_MULTIPROCESSOR=65536,
        MAX_REGISTERS_PER_BLOCK=65536,
        MAX_THREADS_PER_BLOCK=1024,
    )
    limits = device_limits(device)
    assert (limits.max_warps_per_sm, limits.max_blocks_per_sm) == (48, 16)
    # 64 regs: 32 warps by registers, 8 blocks of 4: 32 of 48 warps
    assert theoretical_occupancy(64, 128, limits) == (8, 32, 32 / 48)


def test_a_spent_budget_reads_nothing_and_lists_every_kernel():
    rows = list(read_kernels({"Ogden": None, "NeoHookean": None}, SM90, 128, budget=-1.0))
    assert len(rows) == 2 * 2 * 2 * len(FORMS)  # engines, materials, dtypes, forms
    assert all(r["not_read"] == "budget spent" and "error" not in r for r in rows)
    assert [r["material"] for r in rows[:4]] == ["NeoHookean"] * 4
    assert rows[0]["engine"] == "mjed" and rows[-1]["engine"] == "classical"


def test_one_engine_reads_only_its_kernels():
    rows = list(read_kernels({"Ogden": None}, SM90, 128, budget=-1.0, engines=("classical",)))
    assert len(rows) == 2 * len(FORMS)  # dtypes, forms
    assert {r["engine"] for r in rows} == {"classical"}


def test_an_unknown_engine_is_refused_by_name(capsys):
    with pytest.raises(SystemExit) as exc:
        gpu_occupancy_main(["--engines", "classical,sofa"])
    assert exc.value.code == 2
    assert "--engines: sofa" in capsys.readouterr().err


@pytest.mark.parametrize("simulator", ["1", None])
def test_the_command_refuses_without_a_real_device(tmp_path, simulator):
    env = dict(os.environ, PYTHONPATH=str(ROOT), CUDA_VISIBLE_DEVICES="")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = simulator
    out = tmp_path / "occupancy.json"
    ran = subprocess.run(
        [sys.executable, "-m", "comparisons.timing.gpu_occupancy", "--json", str(out)],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=300,
    )
    assert ran.returncode == 2, ran.stderr[-2000:]
    assert "needs a real NVIDIA GPU" in ran.stderr
    assert ("simulator" in ran.stderr) == bool(simulator)
    assert not out.exists()
