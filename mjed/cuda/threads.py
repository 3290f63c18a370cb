"""The launch configuration of every kernel of the cuda backend: threads per block, and how
many blocks a launch over a number of items runs (:func:`blocks_for`).

Every kernel here walks its items (cells, rows, entries) in a grid-stride loop: thread t of a
grid of G threads takes items t, t + G, t + 2 G, ... Threads combine results only through
atomics: no shared memory, no synchronisation inside a block. Which block size and how many
blocks run a kernel is therefore a question of speed alone, never of the result beyond the
order of the sums (each thread's partial sums and the atomics that combine them): round-off,
which at most moves a residual that sits on a tolerance across it. One kernel,
:func:`mjed.cuda.step_kernels.clear`, runs on one thread (``[1, 1]``) and is no loop.

On a GPU a block has 128 threads (four warps), which keeps the register-heavy cell kernels
resident, and a launch runs one thread per item (ceil(items / 128) blocks; the reductions at
most 256 blocks, the zeroing of the outputs at most 1024), so that each thread's loop runs
once or a few times.

Numba's CUDA simulator starts one operating-system thread per thread of the grid at every
launch (about a quarter of a millisecond each), so there a launch costs in proportion to its
grid, not to its items. It runs blocks of 8 threads and at most 2 blocks a launch: 16 threads
take every item through the stride loop, and a launch still has several threads in a block
and several blocks, so the stride and the atomics across blocks stay exercised on the small
meshes that are simulated. ``MJED_CUDA_THREADS`` (1 to 1024) sets the block size and
``MJED_CUDA_BLOCKS`` (a positive integer) the most blocks of a launch, for either, each read
once at import: for instance to simulate at the GPU's block size, or with a grid as large as
the items.
"""

from __future__ import annotations

import os
from typing import Optional

from mjed.cuda.availability import simulated

__all__ = [
    "BLOCK_CAP",
    "DEVICE_THREADS",
    "REDUCTION_BLOCKS",
    "SIMULATED_BLOCKS",
    "SIMULATED_THREADS",
    "THREADS_PER_BLOCK",
    "ZEROING_BLOCKS",
    "block_cap",
    "blocks_for",
    "threads_per_block",
]

DEVICE_THREADS = 128
SIMULATED_THREADS = 8
#: the most blocks of a launch under the simulator (module docstring)
SIMULATED_BLOCKS = 2
#: the most blocks of a reduction (one atomic per thread into a few scalars)
REDUCTION_BLOCKS = 256
#: the most blocks of the zeroing of a launch's outputs
ZEROING_BLOCKS = 1024
_VARIABLE = "MJED_CUDA_THREADS"
_BLOCKS_VARIABLE = "MJED_CUDA_BLOCKS"
_GRID_LIMIT = 2**31 - 1  # CUDA's largest grid in x


def _positive(environ, name: str, largest: int, what: str) -> Optional[int]:
    """The integer 1..largest that ``environ[name]`` holds, None where it is unset or blank;
    a ValueError naming the variable and its value otherwise.
    """
    raw = environ.get(name, "").strip()
    if not raw:
        return None
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if not 1 <= value <= largest:
        raise ValueError(f"{name}={raw!r}: {what} (an integer from 1 to {largest})")
    return value


def threads_per_block(environ=os.environ) -> int:
    """The block size for the environment ``environ`` (module docstring)."""
    value = _positive(environ, _VARIABLE, 1024, "a block has 1 to 1024 threads")
    if value is None:
        return SIMULATED_THREADS if simulated(environ) else DEVICE_THREADS
    return value


def block_cap(environ=os.environ) -> Optional[int]:
    """The most blocks of any launch for the environment ``environ``: None (no cap beyond a
    launch's own) on a device, :data:`SIMULATED_BLOCKS` under the simulator, unless
    ``MJED_CUDA_BLOCKS`` says otherwise (module docstring).
    """
    value = _positive(environ, _BLOCKS_VARIABLE, _GRID_LIMIT, "a launch runs at least one block")
    if value is None:
        return SIMULATED_BLOCKS if simulated(environ) else None
    return value


#: Threads per block of every kernel (cell kernels, step kernels, CG, models, reductions).
THREADS_PER_BLOCK = threads_per_block()
#: The most blocks of every launch (None: as many as the items need).
BLOCK_CAP = block_cap()


def blocks_for(
    items: int,
    most: Optional[int] = None,
    *,
    threads: int = THREADS_PER_BLOCK,
    cap: Optional[int] = BLOCK_CAP,
) -> int:
    """The blocks of a launch over ``items`` items: one thread per item (ceil(items /
    threads), at least one block), at most ``most`` (a reduction's or the zeroing's own cap)
    and at most ``cap`` (the simulator's; module docstring). Every kernel's stride loop covers
    the items whatever the number.
    """
    blocks = max(1, -(-int(items) // threads))
    for limit in (most, cap):
        if limit is not None:
            blocks = min(blocks, limit)
    return blocks
