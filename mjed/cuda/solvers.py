"""Jacobi-preconditioned conjugate gradients on the device (Numba CUDA), FP64.

:func:`device_conjugate_gradient` solves A x = b with the semantics of
:func:`mjed.solvers.conjugate_gradient` (same tolerance test ||b - A x|| <= tol ||b||, same
stopping reasons, same :class:`mjed.solvers.CGResult`) with A in CSR on the device: the
matrix-vector product over the rows, the vector updates over the entries, the dot products
reduced by one atomic add per thread, each a grid-stride loop (one item a thread on a GPU;
:mod:`mjed.cuda.threads`). The CSR values can come
straight from :meth:`mjed.cuda.CudaForceField.device_force_and_stiffness`, whose pattern is
the field's (``field.pattern``), so that the stiffness never leaves the device.

:class:`mjed.integrator.ImplicitEuler` uses it with ``LinearSolverOptions(solver="cuda-cg")``,
forming its step matrix on the host and copying it here at each solve;
:class:`mjed.cuda.integrator.DeviceImplicitEuler` forms the matrix on the device and solves
through :class:`DeviceCG` (work vectors kept, solution left on the device). Each iteration
reads two pairs of scalars back to the host (p.Ap, then r.r and r.z together: 32 bytes), a few
microseconds per iteration on a GPU. Importing this module imports numba.cuda.
"""

from __future__ import annotations

import math
from typing import Tuple

import numpy as np
from numba import cuda

from mjed.cuda.step_kernels import clear
from mjed.cuda.threads import REDUCTION_BLOCKS, THREADS_PER_BLOCK, blocks_for
from mjed.solvers import CGResult

__all__ = ["DeviceCG", "DeviceCSR", "device_conjugate_gradient"]

_THREADS = THREADS_PER_BLOCK


@cuda.jit
def _spmv(indptr, indices, data, x, y):
    """Y = A x, one thread per row."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, y.shape[0], stride):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * x[indices[k]]
        y[i] = acc


@cuda.jit
def _jacobi(indptr, indices, data, dinv):
    """Dinv = 1 / diag(A), 1 where the diagonal is not positive (as
    mjed.solvers.jacobi_preconditioner).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, dinv.shape[0], stride):
        d = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] == i:
                d += data[k]
        dinv[i] = 1.0 / d if d > 0.0 else 1.0


@cuda.jit
def _dots(a, b, c, out):
    """out[0] += a.b, out[1] += a.c (grid-stride; one atomic add of each per thread)."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    s0 = 0.0
    s1 = 0.0
    for i in range(start, a.shape[0], stride):
        s0 += a[i] * b[i]
        s1 += a[i] * c[i]
    cuda.atomic.add(out, 0, s0)
    cuda.atomic.add(out, 1, s1)


@cuda.jit
def _step(x, r, p, Ap, dinv, z, alpha):
    """X += alpha p; r -= alpha Ap; z = dinv r."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, x.shape[0], stride):
        x[i] += alpha * p[i]
        ri = r[i] - alpha * Ap[i]
        r[i] = ri
        z[i] = dinv[i] * ri


@cuda.jit
def _direction(z, p, beta):
    """P = z + beta p."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, p.shape[0], stride):
        p[i] = z[i] + beta * p[i]


@cuda.jit
def _residual_start(b, Ax, dinv, r, z):
    """R = b - A x; z = dinv r."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, r.shape[0], stride):
        ri = b[i] - Ax[i]
        r[i] = ri
        z[i] = dinv[i] * ri


class DeviceCSR:
    """A square CSR matrix on the device (float64 values, int32 or int64 indices). From a
    SciPy CSR matrix, or from device values with a host pattern (indptr, indices).
    """

    def __init__(self, indptr, indices, data):
        self.n = len(indptr) - 1
        index = np.int32 if max(len(indices), self.n) < 2**31 else np.int64
        self.indptr = cuda.to_device(np.ascontiguousarray(indptr, dtype=index))
        self.indices = cuda.to_device(np.ascontiguousarray(indices, dtype=index))
        on_device = hasattr(data, "copy_to_host")  # a device array (also under the simulator)
        self.data = (
            data if on_device else cuda.to_device(np.ascontiguousarray(data, dtype=np.float64))
        )

    @classmethod
    def from_scipy(cls, A) -> "DeviceCSR":
        A = A.tocsr()
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"A must be square, got {A.shape}")
        return cls(A.indptr, A.indices, A.data)


class DeviceCG:
    """The work vectors of Jacobi-preconditioned CG on systems of size n, kept on the device
    between solves (:meth:`solve` allocates nothing).
    """

    def __init__(self, n: int):
        self.n = n
        self.blocks = blocks_for(n)
        self.reduce_blocks = blocks_for(n, REDUCTION_BLOCKS)
        self.r, self.z, self.p, self.Ap, self.dinv = (cuda.device_array(n) for _ in range(5))
        self.sums = cuda.device_array(2)

    def _dots(self, a, u, v) -> Tuple[float, float]:
        """(a.u, a.v): the only numbers an iteration reads back (16 bytes)."""
        clear[1, 1](self.sums)
        _dots[self.reduce_blocks, _THREADS](a, u, v, self.sums)
        s = self.sums.copy_to_host()
        return float(s[0]), float(s[1])

    def solve(self, M: "DeviceCSR", b, x, nb: float, *, tol: float, max_iterations: int):
        """Solve M x = b in place: b and x (the first guess, then the solution) are device
        arrays (n,); nb = ||b|| > 0. Returns (iterations, converged, reason, residual) with the
        semantics of :func:`mjed.solvers.conjugate_gradient`.
        """
        blocks, r, z, p, Ap, dinv = self.blocks, self.r, self.z, self.p, self.Ap, self.dinv
        _jacobi[blocks, _THREADS](M.indptr, M.indices, M.data, dinv)
        _spmv[blocks, _THREADS](M.indptr, M.indices, M.data, x, Ap)
        _residual_start[blocks, _THREADS](b, Ap, dinv, r, z)
        rr, rz = self._dots(r, r, z)
        res = math.sqrt(rr) / nb
        if res <= tol:
            return 0, True, "converged", res
        p.copy_to_device(z)
        for k in range(1, max_iterations + 1):
            if not (rz > 0.0):
                reason = "non_finite" if not math.isfinite(rz) else "preconditioner_indefinite"
                return k, False, reason, res
            _spmv[blocks, _THREADS](M.indptr, M.indices, M.data, p, Ap)
            pAp, _ = self._dots(p, Ap, Ap)
            if not math.isfinite(pAp):
                return k, False, "non_finite", res
            if pAp <= 0.0:
                return k, False, "negative_curvature", res
            alpha = rz / pAp
            _step[blocks, _THREADS](x, r, p, Ap, dinv, z, alpha)
            rr, rz_new = self._dots(r, r, z)
            res = math.sqrt(rr) / nb
            if res <= tol:
                return k, True, "converged", res
            _direction[blocks, _THREADS](z, p, rz_new / rz)
            rz = rz_new
        return max_iterations, False, "max_iterations", res


def device_conjugate_gradient(
    A, b, *, tol: float = 1e-10, max_iterations: int = 1000, x0=None
) -> CGResult:
    """Solve A x = b for a symmetric A by Jacobi-preconditioned CG on the device.

    Args:
        A: a SciPy sparse matrix (copied to the device) or a :class:`DeviceCSR`.
        b: (N,) host array; x0: first guess (N,) (zero by default).
        tol, max_iterations: as :func:`mjed.solvers.conjugate_gradient`.

    Returns a :class:`mjed.solvers.CGResult` with x on the host.
    """
    M = A if isinstance(A, DeviceCSR) else DeviceCSR.from_scipy(A)
    b = np.asarray(b, dtype=np.float64)
    n = M.n
    if b.shape != (n,):
        raise ValueError(f"b must have shape ({n},), got {b.shape}")
    nb = math.sqrt(float(b @ b))
    x_host = np.zeros(n) if x0 is None else np.array(x0, dtype=np.float64)
    if nb == 0.0:
        return CGResult(x_host, 0, True, "converged", 0.0)
    x = cuda.to_device(x_host)
    iterations, converged, reason, res = DeviceCG(n).solve(
        M, cuda.to_device(b), x, nb, tol=tol, max_iterations=max_iterations
    )
    return CGResult(x.copy_to_host(), iterations, converged, reason, res)
