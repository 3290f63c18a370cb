"""This machine's memory bandwidth, and the time floor it implies for force + stiffness.

Bandwidth: a copy of a 64 MiB float64 array (far larger than the caches), compiled with
Numba when it is installed (NumPy's ``copyto`` otherwise); the best of a few runs, counted
as bytes read plus bytes written over the time (a "copy" figure in the STREAM sense; the
write-allocate read of the destination is not counted).

Floor: whatever the method, force + stiffness must at least write the CSR values and the
force vector once and read the positions, the connectivity and the rest geometry once (the
rest shape vectors D_a (12 doubles) and the volume per cell). Those bytes over the copy
bandwidth are the floor; a method's time divided by it says how far from memory-bound it is.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["Bandwidth", "measure_bandwidth", "floor_bytes", "floor_seconds"]


@dataclass(frozen=True)
class Bandwidth:
    """bytes_per_s: (read + written) bytes per second of the copy; kernel: how it was measured."""

    bytes_per_s: float
    kernel: str
    array_bytes: int
    best_s: float

    def to_dict(self) -> dict:
        return {
            "bytes_per_s": self.bytes_per_s,
            "GB_per_s": self.bytes_per_s / 1e9,
            "kernel": self.kernel,
            "array_bytes": self.array_bytes,
            "best_s": self.best_s,
        }


def _copy_kernel() -> "tuple[Callable, str]":
    from mjed.compiled import numba_available

    if numba_available():
        from numba import njit

        @njit(cache=False, nogil=True)
        def copy(src, dst):
            for i in range(src.shape[0]):
                dst[i] = src[i]

        return copy, "numba loop"
    return (lambda src, dst: np.copyto(dst, src)), "numpy copyto"


def measure_bandwidth(array_bytes: int = 64 * 2**20, repeats: int = 5) -> Bandwidth:
    """Best-of-``repeats`` copy bandwidth of an ``array_bytes`` float64 array (bytes/s, read +
    write).
    """
    if array_bytes < 8 or repeats < 1:
        raise ValueError(
            f"array_bytes must be >= 8 and repeats >= 1, got {array_bytes} and {repeats}"
        )
    n = array_bytes // 8
    src = np.ones(n)
    dst = np.zeros(n)  # touched now, so page faults are not timed
    copy, kernel = _copy_kernel()
    copy(src, dst)  # compile / warm up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        copy(src, dst)
        best = min(best, time.perf_counter() - t0)
    if dst[-1] != 1.0:
        raise RuntimeError("the bandwidth copy kernel did not copy")
    return Bandwidth(2.0 * 8 * n / best, kernel, 8 * n, best)


def floor_bytes(n_nodes: int, n_cells: int, nnz: int, index_bytes: int = 4) -> int:
    """Bytes force + stiffness must move at least: written CSR values (nnz doubles) and force
    (3 n doubles); read positions (3 n doubles), connectivity (4 indices per cell) and rest
    geometry (D: 12 doubles and V0: 1 double per cell).
    """
    written = 8 * nnz + 8 * 3 * n_nodes
    read = 8 * 3 * n_nodes + index_bytes * 4 * n_cells + 8 * 13 * n_cells
    return int(written + read)


def floor_seconds(n_nodes: int, n_cells: int, nnz: int, bandwidth: Bandwidth) -> float:
    """The time floor of force + stiffness on this machine (seconds)."""
    return floor_bytes(n_nodes, n_cells, nnz) / bandwidth.bytes_per_s
