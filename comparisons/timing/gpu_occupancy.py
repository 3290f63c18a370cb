"""What the compiler gave each CUDA cell kernel, and the occupancy that allows.

    python -m comparisons.timing.gpu_occupancy --json OUT.json [--budget SECONDS]

For every declared material, each precision (float64, float32) and each kernel a field
launches (``force``: the kernel without the stiffness code, launched when no stiffness is
asked; ``force+K``: the one that forms everything, :mod:`mjed.cuda.forcefield`), MJED's and
the classical element's (:mod:`reference_fem.classical_cuda`), it launches the field once on
one tetrahedron, so that Numba compiles the kernel for the very types of a real launch, and
reads from numba-cuda's dispatcher the registers per thread, the local memory per thread
(spills and local arrays), the static shared memory per block and the most threads per block.
From the registers and the device's attributes it computes the theoretical occupancy at
:data:`mjed.cuda.launch.THREADS_PER_BLOCK` (:func:`theoretical_occupancy`): the suspect left
by the H200 measurement (docs/studies/timing.md) was the stiffness kernel's registers.

It needs a real device: Numba's CUDA simulator runs kernels as Python and reports no
registers, so under the simulator, or without numba-cuda or a GPU, it says so and exits 2.
Kernels are read MJED's first (the kits step leaves them in the kernel cache), NeoHookean
first; past ``--budget`` seconds the rest are listed as not read.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["OccupancyLimits", "device_limits", "read_kernels", "theoretical_occupancy"]

DTYPES = ("float64", "float32")
FORMS = ("force", "force+K")

#: Registers per warp are allocated in units of this many since compute capability 3.0 (the
#: CUDA occupancy calculator's "register allocation unit size"); the driver does not report it.
REGISTER_UNIT = 256
#: The most registers one thread may have since compute capability 3.5 (not an attribute).
MAX_REGS_PER_THREAD = 255


@dataclass(frozen=True)
class OccupancyLimits:
    """What bounds the blocks resident on one streaming multiprocessor (SM).

    warp_size: threads per warp; max_threads_per_sm: resident threads per SM;
    max_blocks_per_sm: resident blocks per SM; regs_per_sm: 32-bit registers per SM;
    max_regs_per_block: 32-bit registers one block may hold; max_regs_per_thread: registers
    one thread may have; register_unit: registers per warp are allocated in multiples of
    this; max_threads_per_block: the device's launch limit. All counts, positive integers.
    """

    warp_size: int = 32
    max_threads_per_sm: int = 2048
    max_blocks_per_sm: int = 32
    regs_per_sm: int = 65536
    max_regs_per_block: int = 65536
    max_regs_per_thread: int = MAX_REGS_PER_THREAD
    register_unit: int = REGISTER_UNIT
    max_threads_per_block: int = 1024

    def __post_init__(self):
        for name, value in asdict(self).items():
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(
                    f"OccupancyLimits.{name} must be a positive integer, not {value!r}"
                )
        if self.max_threads_per_sm % self.warp_size:
            raise ValueError("OccupancyLimits: max_threads_per_sm is not a whole number of warps")
        if self.max_threads_per_block > self.max_threads_per_sm:
            raise ValueError("OccupancyLimits: a block larger than an SM holds")
        if self.max_regs_per_block > self.regs_per_sm:
            raise ValueError("OccupancyLimits: a block may hold more registers than an SM has")

    @property
    def max_warps_per_sm(self) -> int:
        return self.max_threads_per_sm // self.warp_size


def theoretical_occupancy(
    regs_per_thread: int, threads_per_block: int, limits: OccupancyLimits
) -> Tuple[int, int, float]:
    """(blocks per SM, active warps per SM, occupancy = active / most warps per SM) of a kernel
    of ``regs_per_thread`` 32-bit registers launched with ``threads_per_block`` threads, from
    the registers, the resident threads and the resident blocks alone (the cell kernels use
    no shared memory; shared memory is reported beside). (0, 0, 0.0) when a block cannot run
    (more registers than a block may hold). Raises ValueError for a count out of range.
    """
    if not 1 <= regs_per_thread <= limits.max_regs_per_thread:
        raise ValueError(
            f"regs_per_thread {regs_per_thread} not in 1..{limits.max_regs_per_thread}"
        )
    if not 1 <= threads_per_block <= limits.max_threads_per_block:
        raise ValueError(
            f"threads_per_block {threads_per_block} not in 1..{limits.max_threads_per_block}"
        )
    warps = -(-threads_per_block // limits.warp_size)  # a partial warp occupies a whole one
    unit = limits.register_unit
    regs_per_warp = -(-regs_per_thread * limits.warp_size // unit) * unit
    if regs_per_warp * warps > limits.max_regs_per_block:
        return 0, 0, 0.0
    by_registers = (limits.regs_per_sm // regs_per_warp) // warps
    by_warps = limits.max_warps_per_sm // warps
    blocks = min(by_registers, by_warps, limits.max_blocks_per_sm)
    return blocks, blocks * warps, blocks * warps / limits.max_warps_per_sm


def device_limits(device) -> OccupancyLimits:
    """The limits of a numba-cuda ``Device`` (``cuda.get_current_device()``), read from its
    attributes; the two the driver does not report are the defaults (see the constants).
    """
    return OccupancyLimits(
        warp_size=int(device.WARP_SIZE),
        max_threads_per_sm=int(device.MAX_THREADS_PER_MULTIPROCESSOR),
        max_blocks_per_sm=int(device.MAX_BLOCKS_PER_MULTIPROCESSOR),
        regs_per_sm=int(device.MAX_REGISTERS_PER_MULTIPROCESSOR),
        max_regs_per_block=int(device.MAX_REGISTERS_PER_BLOCK),
        max_threads_per_block=int(device.MAX_THREADS_PER_BLOCK),
    )


def _compiled(dispatcher, reader: str) -> int:
    """One figure of the dispatcher's one compiled overload (numba-cuda returns a dict by
    signature when the kernel is not specialised; a fresh process launched it with one).
    """
    value = getattr(dispatcher, reader)()
    if isinstance(value, dict):
        if len(value) != 1:
            raise RuntimeError(f"{len(value)} compiled signatures, expected the launch's one")
        (value,) = value.values()
    return int(value)


def _reading(dispatcher, limits: OccupancyLimits, threads: int) -> Dict[str, object]:
    regs = _compiled(dispatcher, "get_regs_per_thread")
    blocks, warps, occupancy = theoretical_occupancy(regs, threads, limits)
    return {
        "regs_per_thread": regs,
        "local_bytes_per_thread": _compiled(dispatcher, "get_local_mem_per_thread"),
        "shared_bytes_per_block": _compiled(dispatcher, "get_shared_mem_per_block"),
        "max_threads_per_block": _compiled(dispatcher, "get_max_threads_per_block"),
        "blocks_per_sm": blocks,
        "active_warps_per_sm": warps,
        "occupancy": occupancy,
    }


def _tet():
    """One tetrahedron and positions that stretch it a little (a launch that computes)."""
    from mjed.mesh import TetMesh

    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    return TetMesh(points, np.array([[0, 1, 2, 3]])), points * np.array([1.05, 0.98, 1.0])


def _kernels(engine: str, material, dtype: str) -> Tuple[object, object]:
    """(force kernel, force+K kernel) of ``engine``'s field, each compiled by one launch."""
    from mjed.cuda import CudaForceField
    from reference_fem.classical_cuda import CudaClassicalGalerkin

    mesh, x = _tet()
    if engine == "mjed":
        field = CudaForceField(mesh, material, dtype=np.dtype(dtype))
    else:
        field = CudaClassicalGalerkin(mesh, None, material, dtype=np.dtype(dtype))
    field.force(x)  # the force kernel
    field.force_and_stiffness(x)  # the kernel with the stiffness code
    # the dispatchers the field launches (which one, by the flags: the fields' _launch)
    return field._force_kernel, field._kernel


ENGINES = ("mjed", "classical")


def _order(names: Sequence[str], engines: Sequence[str] = ENGINES) -> List[Tuple[str, str]]:
    """(engine, material): MJED's first (cached by the kits step), NeoHookean (the benchmark's)
    first within each.
    """
    names = sorted(names, key=lambda n: n != "NeoHookean")
    return [(e, n) for e in ENGINES if e in engines for n in names]


def read_kernels(
    materials: Dict[str, object],
    limits: OccupancyLimits,
    threads: int,
    budget: float,
    clock: Callable[[], float] = time.monotonic,
    engines: Sequence[str] = ENGINES,
) -> Iterator[Dict[str, object]]:
    """One row per (engine, material, dtype, form): what :func:`_reading` reads, or ``error``
    (the kernel did not compile or launch), or ``not_read`` (the budget, in seconds, was
    spent before it was started).
    """
    end = clock() + budget
    for engine, name in _order(list(materials), engines):
        for dtype in DTYPES:
            row = {"engine": engine, "material": name, "dtype": dtype}
            if clock() > end:
                yield from ({**row, "form": f, "not_read": "budget spent"} for f in FORMS)
                continue
            start = clock()
            try:
                kernels = _kernels(engine, materials[name], dtype)
                read = [_reading(k, limits, threads) for k in kernels]
            except Exception as exc:  # one kernel's failure is a row, not the end of the run
                read = [{"error": f"{type(exc).__name__}: {exc}"}] * len(FORMS)
            seconds = round(clock() - start, 2)
            for form, values in zip(FORMS, read):
                yield {**row, "form": form, **values, "seconds": seconds}


def _line(row: Dict[str, object]) -> str:
    head = f"{row['engine']:9s} {row['material']:18s} {row['dtype']:7s} {row['form']:8s}"
    if "error" in row or "not_read" in row:
        return f"{head} {row.get('error') or 'not read: ' + row['not_read']}"
    return (
        f"{head} {row['regs_per_thread']:4d} {row['local_bytes_per_thread']:6d}"
        f" {row['shared_bytes_per_block']:6d} {row['blocks_per_sm']:3d}"
        f" {row['active_warps_per_sm']:4d} {100 * row['occupancy']:5.1f} %"
    )


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write the readings and the device's limits here")
    parser.add_argument("--materials", default="all", help="comma-separated, or all")
    parser.add_argument("--budget", type=float, default=90.0, help="seconds of compiling")
    parser.add_argument(
        "--engines",
        default=",".join(ENGINES),
        help="comma-separated among mjed, classical (a session that read one reads the other)",
    )
    args = parser.parse_args(argv)
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    unknown = sorted(set(engines) - set(ENGINES))
    if unknown or not engines:
        parser.error(
            f"--engines: {', '.join(unknown) or 'none given'}; known: {', '.join(ENGINES)}"
        )
    from comparisons.timing.hardware import gpu_status

    why = gpu_status()  # the simulator runs kernels as Python: it has no registers to report
    if why:
        print(f"gpu_occupancy: needs a real NVIDIA GPU: {why}; nothing read", file=sys.stderr)
        return 2
    from common.cases import parse_materials
    from mjed.cuda.availability import load_numba_cuda
    from mjed.cuda.launch import THREADS_PER_BLOCK

    device = load_numba_cuda().get_current_device()
    name = device.name.decode() if isinstance(device.name, bytes) else str(device.name)
    limits = device_limits(device)
    materials = {m.name: m for m in parse_materials(args.materials)}
    print(
        f"{name}, compute capability {device.compute_capability}: threads per block "
        f"{THREADS_PER_BLOCK}, {limits}"
    )
    print(
        f"{'engine':9s} {'material':18s} {'dtype':7s} {'form':8s} regs  local shared"
        " blk warp occupancy"
    )
    rows = []
    for row in read_kernels(materials, limits, THREADS_PER_BLOCK, args.budget, engines=engines):
        print(_line(row), flush=True)
        rows.append(row)
    if args.json:
        document = {
            "device": name,
            "compute_capability": list(device.compute_capability),
            "threads_per_block": THREADS_PER_BLOCK,
            "budget_s": args.budget,
            "limits": asdict(limits),
            "kernels": rows,
        }
        with open(args.json, "w") as out:
            json.dump(document, out, indent=1)
    # a kernel that failed to compile fails the step; the budget's stop is by design
    return 1 if any("error" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
