"""Compiled helpers shared by the generated MJED kernels (mjed.compiled.codegen) and the
generated classical Galerkin kernels (reference_fem.classical_codegen): the compiler options,
the 3x3 symmetric eigen-decomposition, the divided differences of the spectral tangent, the
CSR block sources and the ordered write of the CSR data.

Importing this module imports Numba; :mod:`mjed.compiled` imports it only when a compiled
field is built. The serial kernels scatter into the shared sums without atomics, and the
comparison with the classical kernel stays like for like; the parallel MJED driver runs
coloured slabs of cells that share no node (:mod:`mjed.compiled.schedule`), so it needs no
atomics either, and writes the CSR data and zeroes its sums in parallel loops here.
``error_model="numpy"`` gives IEEE results (NaN for ln J at J <= 0) instead of Python
exceptions inside the kernel; the caller checks J afterwards. No ``fastmath``: with FMA
contraction, reassociation, no-signed-zeros or reciprocal approximations the generated
NeoHookean kernel measured the same (2.42 to 2.46 ms against 2.46 ms on cube-paper), so
strict IEEE arithmetic costs nothing here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = [
    "JIT_OPTIONS",
    "eigh3",
    "eigh3_sym",
    "block_sources",
    "write_csr",
    "write_csr_parallel",
    "zero_sums_parallel",
    "divided_differences",
    "divided_differences_sym",
    "colour_chunks",
    "threads",
    "prefer_passive_wait",
    "DEVICE_HELPERS",
]

#: The compiler options of every kernel (the generated MJED kernels and the classical ones too).
JIT_OPTIONS = dict(cache=True, nogil=True, error_model="numpy")
_JIT = JIT_OPTIONS


# ------------------------------------------------------------------ shared pieces
@njit(**_JIT)
def _rotation(app, aqq, apq, arp, arq):
    """The Jacobi rotation (c, s) zeroing a_pq of a symmetric 3x3 matrix, and the entries it
    changes: a_pp, a_qq and a_rp, a_rq of the third index r.

    With d = a_qq - a_pp, b = 2 a_pq, rho = sqrt(d^2 + b^2), m = |d| + rho: c = m / w and
    |s| = |b| / w, w = sqrt(2 rho m). This is Golub and Van Loan's rotation (t = tan of the
    smaller angle, sign of theta = d / b) with the two divisions and two square roots of
    theta, t and c folded into one division and two square roots (a rotation is a chain of
    dependent divisions and roots, so their number sets its latency).
    """
    d = aqq - app
    b = 2.0 * apq
    rho = math.sqrt(d * d + b * b)
    m = abs(d) + rho
    q = 1.0 / math.sqrt(2.0 * rho * m)
    c = m * q
    s = abs(b) * q
    if (d > 0.0 and b < 0.0) or (d < 0.0 and b > 0.0):  # theta = d / b < 0
        s = -s
    t = s / c
    return app - t * apq, aqq + t * apq, c * arp - s * arq, s * arp + c * arq, c, s


@njit(**_JIT)
def _rotate_columns(c, s, x0p, x0q, x1p, x1q, x2p, x2q):
    """Columns p and q of a 3x3 matrix (x_ip, x_iq) after the rotation (c, s)."""
    return (
        c * x0p - s * x0q,
        s * x0p + c * x0q,
        c * x1p - s * x1q,
        s * x1p + c * x1q,
        c * x2p - s * x2q,
        s * x2p + c * x2q,
    )


@njit(**_JIT)
def eigh3_sym(a00, a01, a02, a11, a12, a22):
    """Eigenvalues and eigenvectors of the symmetric matrix with upper triangle a00 ... a22,
    by cyclic Jacobi rotations in registers (accurate to round-off in every eigenvector).

    Returns (lam0, lam1, lam2, V00, V01, V02, V10, V11, V12, V20, V21, V22), V[:, n] the
    eigenvector of lam_n (unsorted). Entries of physical magnitude are assumed (d^2 + b^2 of
    a rotation must not overflow), as they are for C = F^T F.

    An off-diagonal entry at or below ``tiny`` (1e-17 of the trace's magnitude) is dropped
    instead of rotated: that changes the eigenvalues by less than round-off, and rotating it
    could underflow. In float32 (the CUDA FP32 kernels), with two equal diagonal entries
    (d = 0, at rest or in uniaxial stretch) and a_pq ~ 1e-23, b^2 underflows to 0, so rho = 0
    and c = 0 * inf = NaN; a kept entry has b^2 >= 4 tiny^2, far above float32's smallest.
    """
    v00, v01, v02, v10, v11, v12, v20, v21, v22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    tiny = 1e-17 * (abs(a00) + abs(a11) + abs(a22) + 1e-300)
    tol = tiny * tiny
    for _sweep in range(60):
        if a01 * a01 + a02 * a02 + a12 * a12 <= tol:
            break
        if abs(a01) > tiny:  # (p, q) = (0, 1), r = 2
            a00, a11, a02, a12, c, s = _rotation(a00, a11, a01, a02, a12)
            v00, v01, v10, v11, v20, v21 = _rotate_columns(c, s, v00, v01, v10, v11, v20, v21)
        a01 = 0.0
        if abs(a02) > tiny:  # (0, 2), r = 1
            a00, a22, a01, a12, c, s = _rotation(a00, a22, a02, a01, a12)
            v00, v02, v10, v12, v20, v22 = _rotate_columns(c, s, v00, v02, v10, v12, v20, v22)
        a02 = 0.0
        if abs(a12) > tiny:  # (1, 2), r = 0
            a11, a22, a01, a02, c, s = _rotation(a11, a22, a12, a01, a02)
            v01, v02, v11, v12, v21, v22 = _rotate_columns(c, s, v01, v02, v11, v12, v21, v22)
        a12 = 0.0
    return a00, a11, a22, v00, v01, v02, v10, v11, v12, v20, v21, v22


@njit(**_JIT)
def eigh3(A, lam, V, a):
    """eigh3_sym on arrays: eigenvalues lam (3,) and eigenvectors V (3, 3) (columns) of the
    symmetric A (3, 3) (upper triangle read; A is not changed). a: unused scratch, kept for
    the callers' signature.
    """
    r = eigh3_sym(A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])
    for i in range(3):
        lam[i] = r[i]
        for j in range(3):
            V[i, j] = r[3 + 3 * i + j]


@njit(**_JIT)
def block_sources(indptr, indices, edges, n_nodes):
    """Where each 3x3 node block of the CSR pattern comes from, in pattern order.

    indptr, indices: a CSR pattern of 3x3 node blocks with sorted columns (mjed.sparse.CSRPattern);
    edges: (E, 2) its unique mesh edges (i < j), sorted by (i, j). Returns src (B,) and
    blkptr (n + 1,): block kk of node row i is src[blkptr[i] + kk], 2 e for the edge sum U_e
    (i < j), 2 e + 1 for its transpose (i > j) and -1 for the node's own block.
    """
    deg = np.empty(n_nodes, dtype=np.int64)
    for i in range(n_nodes):
        deg[i] = (indptr[3 * i + 1] - indptr[3 * i]) // 3
    blkptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for i in range(n_nodes):
        blkptr[i + 1] = blkptr[i] + deg[i]
    src = np.empty(blkptr[n_nodes], dtype=np.int64)
    E = edges.shape[0]
    for i in range(n_nodes):
        row0 = indptr[3 * i]
        for kk in range(deg[i]):
            j = indices[row0 + 3 * kk] // 3
            if j == i:
                src[blkptr[i] + kk] = -1
                continue
            lo, hi = (i, j) if i < j else (j, i)
            key = lo * n_nodes + hi
            a, b = 0, E
            while a < b:  # binary search of the sorted edge keys
                mid = (a + b) // 2
                if edges[mid, 0] * n_nodes + edges[mid, 1] < key:
                    a = mid + 1
                else:
                    b = mid
            src[blkptr[i] + kk] = 2 * a + (0 if i < j else 1)
    return src, blkptr


@njit(**_JIT)
def write_csr(U, Dg, src, blkptr, indptr, data):
    """Write every CSR entry once, in order, from the edge sums U and the node blocks Dg.

    The three rows of a node's blocks have the same length L (its block row), so entry (r, c)
    of block kk is at indptr[3 i] + r L + 3 kk + c; the source of a block is decided once
    per block, not per entry (a third faster than branching in the inner loop).
    """
    for i in range(blkptr.shape[0] - 1):
        _write_node_row(i, U, Dg, src, blkptr, indptr, data)


@njit(parallel=True, **_JIT)
def write_csr_parallel(U, Dg, src, blkptr, indptr, data):
    """:func:`write_csr` over the threads: one node row per iteration (each row's entries are
    written by one thread only).
    """
    for i in prange(blkptr.shape[0] - 1):
        _write_node_row(i, U, Dg, src, blkptr, indptr, data)


@njit(parallel=True, **_JIT)
def zero_sums_parallel(U, Dg):
    """U[:] = 0 and Dg[:] = 0 in one parallel loop (one synchronisation of the threads, not two)."""
    E, n = U.shape[0], Dg.shape[0]
    for k in prange(max(E, n)):
        if k < E:
            for r in range(3):
                for c in range(3):
                    U[k, r, c] = 0.0
        if k < n:
            for r in range(3):
                for c in range(3):
                    Dg[k, r, c] = 0.0


# A plain call, not inline="always": Numba's inlining deep-copies the IR, which took 5 of the
# 7 s that compiling write_csr and write_csr_parallel cost with empty caches; the assembled
# stiffness is no slower (64k cells, NeoHookean: 11.6 ms either way).
@njit(**_JIT)
def _write_node_row(i, U, Dg, src, blkptr, indptr, data):
    """The CSR entries of node row i (see write_csr)."""
    p0 = indptr[3 * i]
    L = indptr[3 * i + 1] - p0
    for kk in range(blkptr[i + 1] - blkptr[i]):
        s = src[blkptr[i] + kk]
        p = p0 + 3 * kk
        if s < 0:
            for r in range(3):
                for c in range(3):
                    data[p + r * L + c] = Dg[i, r, c]
        elif s % 2 == 0:
            ge = s // 2
            for r in range(3):
                for c in range(3):
                    data[p + r * L + c] = U[ge, r, c]
        else:
            ge = s // 2
            for r in range(3):
                for c in range(3):
                    data[p + r * L + c] = U[ge, c, r]


# ------------------------------------------------------------------ the spectral tangent
@njit(**_JIT)
def divided_differences(lam, lp, p, theta):
    """theta_nl = (lam_n^p - lam_l^p)/(lam_n - lam_l), limit p lam^(p-1) on ties, symmetric,
    into theta (3, 3): :func:`divided_differences_sym` on arrays.
    """
    r = divided_differences_sym(lam[0], lam[1], lam[2], lp[0], lp[1], lp[2], p)
    theta[0, 0], theta[0, 1], theta[0, 2], theta[1, 1], theta[1, 2], theta[2, 2] = r
    theta[1, 0], theta[2, 0], theta[2, 1] = r[1], r[2], r[4]


@njit(**_JIT)
def divided_differences_sym(lam0, lam1, lam2, lp0, lp1, lp2, p):
    """theta_nl = (lam_n^p - lam_l^p)/(lam_n - lam_l), limit p lam^(p-1) on ties, as scalars:
    (theta00, theta01, theta02, theta11, theta12, theta22) (no arrays, so it runs unchanged in
    a thread of a parallel loop and as a CUDA device function).

    lp_n: lam_n^p. Eigenvalues 5 % or more apart use the quotient of the powers directly (its
    rounding error is below 1e-13 relative there); closer ones use
    lam_l^(p-1) expm1(p log1p(x))/x, x = (lam_n - lam_l)/lam_l, which has no cancellation,
    as mjed.spectral.power_divided_differences does for every pair. Three transcendental
    calls per close pair instead of per pair keeps the spectral tangent affordable.
    """
    return (
        p * lp0 / lam0,
        _dd_pair(lam0, lam1, lp0, lp1, p),
        _dd_pair(lam0, lam2, lp0, lp2, p),
        p * lp1 / lam1,
        _dd_pair(lam1, lam2, lp1, lp2, p),
        p * lp2 / lam2,
    )


@njit(**_JIT)
def _dd_pair(a, b, lpa, lpb, p):
    """(a^p - b^p)/(a - b) from lpa = a^p, lpb = b^p (see divided_differences_sym)."""
    x = (a - b) / b
    if abs(x) >= 0.05:
        return (lpa - lpb) / (a - b)
    return 0.5 * (_dd_close(a, b, p) + _dd_close(b, a, p))


@njit(**_JIT)
def _dd_close(a, b, p):
    """(a^p - b^p)/(a - b) for a close to b, without cancellation."""
    x = (a - b) / b
    if abs(x) < 1e-12:
        ratio = p * (1.0 + 0.5 * (p - 1.0) * x)
    else:
        ratio = math.expm1(p * math.log1p(x)) / x
    return b ** (p - 1.0) * ratio


#: The compiled helpers a generated kernel may call, in an order where each comes after the
#: helpers it calls: a CUDA module (mjed.cuda.codegen) compiles their Python source again as
#: device functions, so the CPU and GPU kernels share one implementation of each.
DEVICE_HELPERS = (
    _rotation,
    _rotate_columns,
    eigh3_sym,
    _dd_close,
    _dd_pair,
    divided_differences_sym,
)


# ------------------------------------------------------------------ the parallel kernel
def threads() -> int:
    """The number of threads Numba's parallel loops use now (starts Numba's thread pool)."""
    import numba

    return int(numba.get_num_threads())


def prefer_passive_wait() -> None:
    """Ask OpenMP threads to sleep, not spin, while they wait, unless the user chose otherwise
    (``OMP_WAIT_POLICY`` already set); effective only before Numba starts its thread pool.

    Why: with Numba's OpenMP threading layer (GNU libgomp) a thread that reaches the end of a
    parallel loop first spins until the others arrive. On a machine whose cores are shared
    with other work, the spinning thread takes CPU time from the one it waits for: measured
    on the 2-core test machine (load average 3), the parallel force + stiffness on cube-paper
    took 11 to 23 ms with spinning threads and 2.9 ms with sleeping ones (one thread: 2.7 ms;
    NUMBA_THREADING_LAYER=workqueue, whose threads sleep too: 3.6 ms). On idle cores sleeping
    costs one wake-up per parallel loop (three per call), microseconds against milliseconds.
    """
    import os

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


@njit(cache=True)
def colour_chunks(cells, chunk_ptr, n_nodes):
    """A greedy colouring of chunks of cells (chunk k: cells chunk_ptr[k] to chunk_ptr[k + 1]
    - 1) such that no two chunks of one colour share a node: the chunks of one colour may then
    add into the node and edge sums from different threads without a race. Returns the colour
    of each chunk (the smallest not used by a chunk sharing a node; at most 512 colours).
    """
    n_chunks = chunk_ptr.shape[0] - 1
    words = 8
    used = np.zeros((n_nodes, words), dtype=np.uint64)
    colour = np.empty(n_chunks, dtype=np.int64)
    forbidden = np.zeros(words, dtype=np.uint64)
    one = np.uint64(1)
    for k in range(n_chunks):
        forbidden[:] = 0
        for e in range(chunk_ptr[k], chunk_ptr[k + 1]):
            for a in range(4):
                for w in range(words):
                    forbidden[w] |= used[cells[e, a], w]
        c = 0
        while c < 64 * words and (forbidden[c // 64] >> np.uint64(c % 64)) & one:
            c += 1
        if c == 64 * words:
            raise ValueError("colour_chunks: more than 512 colours")
        colour[k] = c
        for e in range(chunk_ptr[k], chunk_ptr[k + 1]):
            for a in range(4):
                used[cells[e, a], c // 64] |= one << np.uint64(c % 64)
    return colour
