"""mjed.cuda.threads: one block size for every kernel, smaller on the simulator, and kernels
whose results cannot depend on it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mjed.cuda.threads import DEVICE_THREADS, SIMULATED_THREADS, threads_per_block

CUDA = Path(__file__).resolve().parents[1] / "mjed" / "cuda"


def test_the_simulator_runs_small_blocks_and_a_device_four_warps():
    assert threads_per_block({}) == DEVICE_THREADS == 128
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "0"}) == DEVICE_THREADS
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "1"}) == SIMULATED_THREADS == 8


def test_the_variable_sets_the_size_for_either():
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "1", "MJED_CUDA_THREADS": "128"}) == 128
    assert threads_per_block({"MJED_CUDA_THREADS": " 32 "}) == 32


@pytest.mark.parametrize("raw", ["0", "-8", "2048", "many", "8.5"])
def test_a_size_no_block_can_have_is_refused_naming_the_variable(raw):
    with pytest.raises(ValueError, match=f"MJED_CUDA_THREADS='{re.escape(raw)}'"):
        threads_per_block({"MJED_CUDA_THREADS": raw})


def test_no_kernel_shares_memory_or_synchronises_a_block():
    """What makes the block size a question of speed alone (mjed.cuda.threads): a kernel that
    used shared memory or __syncthreads could depend on it, and would need tests at the device's
    block size, which the simulator then does not run.
    """
    sources = {p.name: p.read_text() for p in CUDA.glob("*.py") if p.name != "threads.py"}
    assert "step_kernels.py" in sources and "codegen.py" in sources
    for name, text in sources.items():
        for word in ("cuda.shared", "syncthreads", "threadfence_block", "blockDim", "threadIdx"):
            assert word not in text, (name, word)
    # and no block size written in a launch but one thread ([1, 1], a few scalars cleared):
    # every other launch takes THREADS_PER_BLOCK
    for name, text in sources.items():
        assert not re.search(r"\[[^\[\]]*,\s*(?!1\s*\])\d+\s*\]\(", text), name
