"""The number of threads in a block, for every kernel of the cuda backend.

Every kernel here gives each thread its own items (a cell, a row, an entry), behind a bounds
check or in a grid-stride loop, and combines results across threads only through atomics: no
shared memory, no synchronisation inside a block. Which block size runs a kernel is therefore
a question of speed alone, never of the result beyond the order of the atomic sums (round-off).

On a GPU a block has 128 threads (four warps), which keeps the register-heavy cell kernels
resident. Numba's CUDA simulator starts one operating-system thread per thread of a block at
every launch, so there a launch costs in proportion to the block: it runs blocks of 8 threads,
which still puts several threads in a block and several blocks in a launch on the small meshes
that are simulated. ``MJED_CUDA_THREADS`` (a positive integer, read once at import) sets the
size for either, for instance to simulate at the GPU's size.
"""

from __future__ import annotations

import os

from mjed.cuda.availability import simulated

__all__ = ["THREADS_PER_BLOCK", "DEVICE_THREADS", "SIMULATED_THREADS", "threads_per_block"]

DEVICE_THREADS = 128
SIMULATED_THREADS = 8
_VARIABLE = "MJED_CUDA_THREADS"


def threads_per_block(environ=os.environ) -> int:
    """The block size for the environment ``environ`` (module docstring)."""
    raw = environ.get(_VARIABLE, "").strip()
    if not raw:
        return SIMULATED_THREADS if simulated(environ) else DEVICE_THREADS
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if not 1 <= value <= 1024:
        raise ValueError(f"{_VARIABLE}={raw!r}: a block has 1 to 1024 threads (an integer)")
    return value


#: Threads per block of every kernel (cell kernels, step kernels, CG, models, reductions).
THREADS_PER_BLOCK = threads_per_block()
