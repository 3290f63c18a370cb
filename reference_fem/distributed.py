"""MPI helpers for the oracle: errors raised on one rank reach every rank, and owned rows of
vectors and matrices are gathered on rank 0 in global dof order.

Why collective errors: a check that fails on one rank only (bad input validated on rank 0, a
non-finite value in one rank's share of the cells) would otherwise leave the other ranks
waiting forever in the next collective call. Every rank raises the same error instead.

The gathers rely on dolfinx's ownership layout: rank r owns the contiguous global dof-node
range ``[offset_r, offset_r + owned_r)`` and ranks are in order, so concatenating the owned
rows of ranks 0, 1, ... gives the global dof order. Plain pickled gathers are enough: the
oracle is a reference for meshes of tens of thousands of cells, not a production solver.
"""

from __future__ import annotations

import sys
import traceback
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Optional, Tuple

import numpy as np

__all__ = [
    "RankError",
    "abort_on_error",
    "on_root",
    "collective",
    "all_finite",
    "gather_rows",
    "gather_csr",
]

ROOT = 0


class RankError(RuntimeError):
    """Raised on every rank when a collective step failed on some rank."""


@contextmanager
def abort_on_error(comm) -> Iterator[None]:
    """With several ranks, an exception escaping the block aborts the whole MPI job.

    The oracle's own checks raise on every rank together, but a failure in code that runs
    on rank 0 only (MJED, the comparison, writing files) would leave the other ranks
    waiting in their next collective call forever. In serial the exception propagates.
    """
    try:
        yield
    except BaseException as exc:
        if comm.size == 1 or isinstance(exc, SystemExit) and not exc.code:
            raise
        traceback.print_exc()
        print(f"rank {comm.rank}: aborting the MPI job", file=sys.stderr, flush=True)
        comm.Abort(1)


def on_root(comm, fn: Callable[..., Any], *args) -> Any:
    """``fn(*args)`` evaluated on rank 0 and broadcast; an exception there is raised on all ranks.

    In serial (``comm.size == 1``) this is just ``fn(*args)``.
    """
    if comm.size == 1:
        return fn(*args)
    payload = None
    if comm.rank == ROOT:
        try:
            payload = ("ok", fn(*args))
        except Exception as exc:  # re-raised below, on every rank
            payload = ("error", exc)
    status, value = comm.bcast(payload, root=ROOT)
    if status == "error":
        raise value
    return value


def collective(comm, fn: Callable[..., Any], *args) -> Any:
    """``fn(*args)`` on every rank; if it raised anywhere, every rank raises.

    The rank that failed raises its own exception; the others raise :class:`RankError`
    naming it, so a run under mpirun stops instead of hanging.
    """
    error: Optional[BaseException] = None
    result = None
    try:
        result = fn(*args)
    except Exception as exc:
        error = exc
    if comm.size == 1:
        if error is not None:
            raise error
        return result
    messages = comm.allgather(None if error is None else f"{type(error).__name__}: {error}")
    if error is not None:
        raise error
    failed = [(r, msg) for r, msg in enumerate(messages) if msg is not None]
    if failed:
        rank, msg = failed[0]
        raise RankError(f"rank {rank} failed: {msg}")
    return result


def all_finite(comm, values: np.ndarray) -> bool:
    """True on every rank if ``values`` are finite on every rank."""
    ok = bool(np.all(np.isfinite(values)))
    return ok if comm.size == 1 else bool(comm.allreduce(ok, op=_land()))


def _land():
    from mpi4py import MPI

    return MPI.LAND


def gather_rows(comm, owned: np.ndarray) -> Optional[np.ndarray]:
    """This rank's owned entries (k_r, ...) concatenated over ranks on rank 0; None elsewhere."""
    if comm.size == 1:
        return owned
    parts = comm.gather(np.ascontiguousarray(owned), root=ROOT)
    return np.concatenate(parts) if comm.rank == ROOT else None


def gather_csr(
    comm, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Owned rows of a distributed CSR matrix (global column indices) stacked on rank 0.

    Args:
        indptr: (rows_r + 1,) row pointers of this rank's owned rows.
        indices: (nnz_r,) global column indices.
        data: (nnz_r,) values.

    Returns:
        (indptr, indices, data) of all rows in global order on rank 0, None elsewhere.
    """
    if comm.size == 1:
        return indptr, indices, data
    parts = comm.gather((np.asarray(indptr), np.asarray(indices), np.asarray(data)), root=ROOT)
    if comm.rank != ROOT:
        return None
    offsets = np.cumsum([0] + [p[0][-1] for p in parts[:-1]])
    indptr_all = np.concatenate([[0]] + [p[0][1:] + off for p, off in zip(parts, offsets)])
    return (
        indptr_all.astype(np.int64),
        np.concatenate([p[1] for p in parts]).astype(np.int64),
        np.concatenate([p[2] for p in parts]),
    )
