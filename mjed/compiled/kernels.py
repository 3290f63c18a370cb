"""Numba kernels: the MJED per-element kernel over a lowered term table, and the pieces the
compiled classical Galerkin shares (3x3 symmetric eigen-decomposition, CSR block positions,
scatter of element blocks).

Importing this module imports Numba; :mod:`mjed.compiled` imports it only when a compiled
field is built. Every kernel is serial (one thread): the scatter into the shared CSR array
then needs no atomics, and the comparison with the classical kernel stays like for like.
``error_model="numpy"`` gives IEEE results (NaN for ln J at J <= 0) instead of Python
exceptions inside the kernel; the caller checks J afterwards.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["eigh3", "deformation_gradient", "apply_to_shape_vectors", "block_sources", "add_edge_blocks", "write_csr", "mjed_cells"]

#: The compiler options of every kernel (the generated MJED kernels and the classical ones too).
JIT_OPTIONS = dict(cache=True, nogil=True, error_model="numpy")
_JIT = JIT_OPTIONS
# Small helpers are inlined into the kernel at Numba IR level: a call per term and cell with a
# dozen array arguments would otherwise cost more than the arithmetic it does.
_INLINE = dict(_JIT, inline="always")

# The six edges (a, b), a < b, in mjed.sparse.EDGES order.
_EA = np.array([0, 0, 0, 1, 1, 2])
_EB = np.array([1, 2, 3, 2, 3, 3])


# ------------------------------------------------------------------ shared pieces
@njit(**_JIT)
def eigh3(A, lam, V, a):
    """Eigenvalues lam (3,) and eigenvectors V (3, 3) (columns) of the symmetric A (3, 3),
    by cyclic Jacobi rotations (accurate to round-off in every eigenvector; A is not changed).
    a: (3, 3) scratch."""
    for i in range(3):
        for j in range(3):
            a[i, j] = A[i, j]
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    scale = abs(a[0, 0]) + abs(a[1, 1]) + abs(a[2, 2]) + 1e-300
    for _sweep in range(60):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        if off <= (1e-17 * scale) ** 2:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p, q]
            if apq == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):
                akp, akq = a[k, p], a[k, q]
                a[k, p] = c * akp - s * akq
                a[k, q] = s * akp + c * akq
            for k in range(3):
                apk, aqk = a[p, k], a[q, k]
                a[p, k] = c * apk - s * aqk
                a[q, k] = s * apk + c * aqk
            a[p, q] = 0.0
            a[q, p] = 0.0
            for k in range(3):
                vkp, vkq = V[k, p], V[k, q]
                V[k, p] = c * vkp - s * vkq
                V[k, q] = s * vkp + c * vkq
    for i in range(3):
        lam[i] = a[i, i]


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


@njit(**_INLINE)
def add_edge_blocks(U, Dg, cells, cell_edges, cell_flip, e, K, scale, Kd, node_blocks):
    """Add scale K (6, 3, 3), the blocks of the six edges (a, b) of cell e (mjed.sparse.EDGES
    order), to the sums of their mesh edges (U (E, 3, 3), oriented from the lower node
    number). node_blocks: also subtract each from both node blocks Dg (n, 3, 3), K_aa =
    -sum_b K_ab (translation invariance, MJED's route), summed per cell first in Kd (4, 3, 3)."""
    if node_blocks:
        for a in range(4):
            for r in range(3):
                for c in range(3):
                    Kd[a, r, c] = 0.0
    for k in range(6):
        ge = cell_edges[e, k]
        flip = cell_flip[e, k]
        a, b = _EA[k], _EB[k]
        for r in range(3):
            for c in range(3):
                v = scale * K[k, r, c]
                if flip:
                    U[ge, c, r] += v
                else:
                    U[ge, r, c] += v
                Kd[a, r, c] -= v
                Kd[b, c, r] -= v
    if node_blocks:
        for a in range(4):
            na = cells[e, a]
            for r in range(3):
                for c in range(3):
                    Dg[na, r, c] += Kd[a, r, c]


@njit(**_JIT)
def write_csr(U, Dg, src, blkptr, indptr, data):
    """Write every CSR entry once, in order, from the edge sums U and the node blocks Dg."""
    n = blkptr.shape[0] - 1
    for i in range(n):
        for kk in range(blkptr[i + 1] - blkptr[i]):
            s = src[blkptr[i] + kk]
            for r in range(3):
                p = indptr[3 * i + r] + 3 * kk
                for c in range(3):
                    if s < 0:
                        data[p + c] = Dg[i, r, c]
                    elif s % 2 == 0:
                        data[p + c] = U[s // 2, r, c]
                    else:
                        data[p + c] = U[s // 2, c, r]


@njit(**_INLINE)
def deformation_gradient(x, cells, D, e, F):
    """F = sum_a x_a (x) D_a of cell e, into F (3, 3)."""
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for a in range(4):
                acc += x[cells[e, a], i] * D[e, a, j]
            F[i, j] = acc


@njit(**_INLINE)
def apply_to_shape_vectors(M, D, e, out):
    """out[a] = M D_a for the four rest shape vectors of cell e: M (3, 3), out (4, 3)."""
    for a in range(4):
        for i in range(3):
            out[a, i] = M[i, 0] * D[e, a, 0] + M[i, 1] * D[e, a, 1] + M[i, 2] * D[e, a, 2]


@njit(**_INLINE)
def _zero3(A, B, C):
    """Zero three (3, 3) arrays."""
    for i in range(3):
        for j in range(3):
            A[i, j] = 0.0
            B[i, j] = 0.0
            C[i, j] = 0.0


@njit(**_INLINE)
def _matmul3(A, B, out):
    """out = A B for (3, 3) arrays."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


# ------------------------------------------------------------------ the functions of J
@njit(**_INLINE)
def _jfunction(kind, P, t, J):
    """f, f', f'' of the J-function of code ``kind`` (mjed.compiled.lowering.J_KINDS) with
    parameters P[t] (rows are indexed, not sliced: a slice costs a reference count)."""
    if kind == 0:  # JPower
        q = P[t, 0]
        if q == 0.0:
            return 1.0, 0.0, 0.0
        Jp2 = J ** (q - 2.0)
        return Jp2 * J * J, q * Jp2 * J, q * (q - 1.0) * Jp2
    L = math.log(J)
    if kind == 1:  # LogPolynomial
        a2, a1, a0 = P[t, 0], P[t, 1], P[t, 2]
        return (a2 * L + a1) * L + a0, (2.0 * a2 * L + a1) / J, (2.0 * a2 * (1.0 - L) - a1) / (J * J)
    k, c = P[t, 0], P[t, 1]  # JLogJ
    return k * (J * L - J + 1.0) + c, k * L, k / J


# ------------------------------------------------------------------ the invariant functions
@njit(**_JIT)
def divided_differences(lam, lp, p, theta):
    """theta_nl = (lam_n^p - lam_l^p)/(lam_n - lam_l), limit p lam^(p-1) on ties, symmetric.

    lp: lam^p. Eigenvalues 5 % or more apart use the quotient of the powers directly (its
    rounding error is below 1e-13 relative there); closer ones use
    lam_l^(p-1) expm1(p log1p(x))/x, x = (lam_n - lam_l)/lam_l, which has no cancellation,
    as mjed.spectral.power_divided_differences does for every pair. Three transcendental
    calls per close pair instead of per pair keeps the spectral tangent affordable."""
    for n in range(3):
        theta[n, n] = p * lp[n] / lam[n]
        for l in range(n + 1, 3):
            x = (lam[n] - lam[l]) / lam[l]
            if abs(x) >= 0.05:
                v = (lp[n] - lp[l]) / (lam[n] - lam[l])
            else:
                v1 = _dd_close(lam[n], lam[l], p)
                v2 = _dd_close(lam[l], lam[n], p)
                v = 0.5 * (v1 + v2)
            theta[n, l] = v
            theta[l, n] = v


@njit(**_JIT)
def _dd_close(a, b, p):
    """(a^p - b^p)/(a - b) for a close to b, without cancellation."""
    x = (a - b) / b
    if abs(x) < 1e-12:
        ratio = p * (1.0 + 0.5 * (p - 1.0) * x)
    else:
        ratio = math.expm1(p * math.log1p(x)) / x
    return b ** (p - 1.0) * ratio


# One small function per kind, each given only the arrays it reads or writes: a single
# function over every kind took a dozen array arguments, and their reference counting cost
# more than the arithmetic (about 100 ns per term and cell on the test machine).
@njit(**_JIT)
def _diag_stress(s, S):
    for i in range(3):
        for j in range(3):
            S[i, j] = s if i == j else 0.0


@njit(**_JIT)
def _g_i1power(c, n, I1, S, coef):
    """g = c I1^n: S = 2 c n I1^(n-1) Id; coefficient 2 c n (n-1) I1^(n-2) (first kind, Id)."""
    if n == 1.0:
        _diag_stress(2.0 * c, S)
        return c * I1
    _diag_stress(2.0 * c * n * I1 ** (n - 1.0), S)
    if n >= 2.0:
        coef[0] = 2.0 * c * n * (n - 1.0) * I1 ** (n - 2.0)
    return c * I1 ** n


@njit(**_JIT)
def _g_linear_i2(c, I1, I2, C, S, coef):
    """g = c I2: S = 2 c (I1 Id - C); coefficients 2c (first), -2c (second)."""
    for i in range(3):
        for j in range(3):
            S[i, j] = 2.0 * c * ((I1 if i == j else 0.0) - C[i, j])
    coef[0] = 2.0 * c
    coef[1] = -2.0 * c
    return c * I2


@njit(**_JIT)
def _g_green_lagrange(mu, lm, C, S, coef):
    """g = lam/2 (tr E)^2 + mu E:E: S = lam tr E Id + 2 mu E; coefficients lam/2, mu."""
    trE = 0.5 * (C[0, 0] + C[1, 1] + C[2, 2]) - 1.5
    EE = 0.0
    for i in range(3):
        for j in range(3):
            Eij = 0.5 * (C[i, j] - (1.0 if i == j else 0.0))
            EE += Eij * Eij
            S[i, j] = 2.0 * mu * Eij + (lm * trE if i == j else 0.0)
    coef[0] = 0.5 * lm
    coef[1] = mu
    return 0.5 * lm * trE * trE + mu * EE


@njit(**_JIT)
def _g_fibre(P, t, Rs, r0, C, S, coef, W1, W2):
    """g = sum B_ij (R^T E R)_ij^2 (B = P[t, :9], R = Rs[t, r0]): S = 2 R (B o R^T E R) R^T;
    coefficients the signs P[t, 9:12] of the split of B. W1, W2: (3, 3) scratch."""
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += 0.5 * (C[i, k] - (1.0 if i == k else 0.0)) * Rs[t, r0, k, j]
            W1[i, j] = acc
    g = 0.0
    for i in range(3):
        for j in range(3):
            ef = 0.0
            for k in range(3):
                ef += Rs[t, r0, k, i] * W1[k, j]
            b = P[t, 3 * i + j]
            g += b * ef * ef
            W2[i, j] = b * ef
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                for l in range(3):
                    acc += Rs[t, r0, i, k] * W2[k, l] * Rs[t, r0, j, l]
            S[i, j] = 2.0 * acc
    for k in range(3):
        coef[k] = P[t, 9 + k]
    return g


@njit(**_JIT)
def _g_eigen_power(c, q, mode, lam, V, S, theta, lp, tangent):
    """g = c sum lam_n^q: S = 2 c q sum lam_n^(q-1) v_n v_n^T; theta = 2 c q times the divided
    differences of lam^(q-1) (exact, mode 0) or SOFA's coaxial approximation (mode 1)."""
    lp[0], lp[1], lp[2] = lam[0] ** (q - 1.0), lam[1] ** (q - 1.0), lam[2] ** (q - 1.0)
    g = lp[0] * lam[0] + lp[1] * lam[1] + lp[2] * lam[2]
    for i in range(3):
        for j in range(3):
            acc = V[i, 0] * lp[0] * V[j, 0] + V[i, 1] * lp[1] * V[j, 1] + V[i, 2] * lp[2] * V[j, 2]
            S[i, j] = 2.0 * c * q * acc
    if not tangent:
        return c * g
    pp = q - 1.0
    if mode == 0.0:
        divided_differences(lam, lp, pp, theta)
    else:
        for n in range(3):
            for l in range(3):
                theta[n, l] = pp * lam[n] ** (0.5 * (pp - 1.0)) * lam[l] ** (0.5 * (pp - 1.0))
    for n in range(3):
        for l in range(3):
            theta[n, l] *= 2.0 * c * q
    return c * g


@njit(**_INLINE)
def _pk2(Sbar, cof, J, h, out, e):
    """out[e] = S = 2 dW/dC = S-bar + h J C^-1 (dJ/dC = J C^-1 / 2, J C^-1 = cof^T cof / J)."""
    hJ = h / J
    for i in range(3):
        for j in range(3):
            out[e, i, j] = Sbar[i, j] + hJ * (cof[0, i] * cof[0, j] + cof[1, i] * cof[1, j] + cof[2, i] * cof[2, j])


# ------------------------------------------------------------------ the MJED kernel
@njit(**_JIT)
def mjed_cells(x, cells, D, V0, DxD, jkind, jpar, gkind, gpar, gmat, npair, tslot, group_start, group_exp,
               group_coef, slot_kind, slot_ident, slot_M, slot_DMD, need_eig, regularize, want_force,
               want_stiffness, want_stress, cell_edges, cell_flip, U, Dg, src, blkptr, indptr, force, data, J_out,
               stress_out):
    """Energy, forces and stiffness of every cell by MJED, from the term table.

    x (n, 3) positions; cells (m, 4); D (m, 4, 3); V0 (m,); the term table of
    mjed.compiled.lowering.TermTable; cell_edges (m, 6) mesh edge of each cell edge,
    cell_flip (m, 6) whether it runs against the mesh edge (mjed.sparse.CSRPattern); U (E, 3, 3), Dg (n, 3, 3):
    scratch for the edge sums and node blocks; src, blkptr (block_sources), indptr: where
    each CSR block comes from.
    Adds -dW/dx into ``force`` (n, 3) if want_force and d2W/dx2 into ``data`` (nnz,) if
    want_stiffness; writes J per cell into J_out (m,) and, if want_stress, the second
    Piola-Kirchhoff stress S = 2 dW/dC per cell into stress_out (m, 3, 3). Returns the total
    energy.

    Per cell, with u, S-bar, S-hat, h, g2 and the slot weights summed over the terms of each
    group and the groups folded in with weight c (plain) or c e^u (exponential), as in
    mjed/engine.py: gradient_a = F S-bar D_a + h d_a and the six edge blocks
      (D_a . S-bar D_b) Id + first: 2 w (F A D_a)(x)(F A D_b)
      + second: w ((F B D_b)(x)(F B D_a) + (D_a . B D_b) F B F^T) + spectral outers
      + d_a (x) (F S-hat D_b + g2 d_b) + F S-hat D_a (x) d_b + c e^u du_a (x) du_b
      + h eps (F (D_a x D_b)),
    summed per mesh edge (node blocks by translation invariance), then every CSR entry written
    once, in order (write_csr): half the scattered updates of adding 16 blocks per cell into
    the CSR array, and the output written as one stream.
    """
    m = cells.shape[0]
    T = jkind.shape[0]
    G = group_exp.shape[0]
    nS = slot_kind.shape[0]
    per_cell_M = slot_M.shape[1] > 1
    per_cell_R = gmat.shape[1] > 1
    F = np.empty((3, 3))
    cof = np.empty((3, 3))
    C = np.empty((3, 3))
    lam = np.zeros(3)
    V = np.eye(3)
    Sk = np.empty((3, 3))
    coef = np.zeros(3)
    theta_k = np.zeros((3, 3))
    W1 = np.empty((3, 3))
    W2 = np.empty((3, 3))
    Sg = np.empty((3, 3))
    Shg = np.empty((3, 3))
    thg = np.empty((3, 3))
    wg = np.empty(nS)
    St = np.empty((3, 3))
    Sh = np.empty((3, 3))
    th = np.empty((3, 3))
    w = np.empty(nS)
    du = np.empty((G, 4, 3))
    escale = np.empty(G)
    d = np.empty((4, 3))
    grad = np.empty((4, 3))
    FSh = np.empty((4, 3))
    SD = np.empty((4, 3))
    M3 = np.empty((3, 3))
    Gs = np.empty((nS, 4, 3))
    FMF = np.empty((nS, 3, 3))
    wn = np.empty((3, 3))  # [n, i] = (F v_n)_i
    cn = np.empty((3, 4))  # [n, a] = v_n . D_a
    K = np.empty((6, 3, 3))
    Kd = np.empty((4, 3, 3))
    MD = np.empty(3)
    lp3 = np.empty(3)
    if want_stiffness:
        U[:] = 0.0
        Dg[:] = 0.0
    energy = 0.0
    for e in range(m):
        # ---- kinematics
        deformation_gradient(x, cells, D, e, F)
        for i in range(3):
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                cof[i, j] = F[i1, j1] * F[i2, j2] - F[i1, j2] * F[i2, j1]
        J = F[0, 0] * cof[0, 0] + F[1, 0] * cof[1, 0] + F[2, 0] * cof[2, 0]
        J_out[e] = J
        for i in range(3):
            for j in range(3):
                C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
        I1 = C[0, 0] + C[1, 1] + C[2, 2]
        CC = 0.0
        for i in range(3):
            for j in range(3):
                CC += C[i, j] * C[i, j]
        I2 = 0.5 * (I1 * I1 - CC)
        if need_eig:
            eigh3(C, lam, V, W1)

        # ---- terms, groups
        _zero3(St, Sh, th)
        for s in range(nS):
            w[s] = 0.0
        h = 0.0
        g2 = 0.0
        has_S = False
        has_Sh = False
        has_th = False
        e_cell = 0.0
        for grp in range(G):
            u = 0.0
            hg = 0.0
            g2g = 0.0
            _zero3(Sg, Shg, thg)
            for s in range(nS):
                wg[s] = 0.0
            for t in range(group_start[grp], group_start[grp + 1]):
                f, df, d2f = _jfunction(jkind[t], jpar, t, J)
                kind = gkind[t]  # mjed.compiled.lowering.G_KINDS
                stressed = kind != 0
                if kind == 0:  # Unity
                    g = 1.0
                elif kind == 1:
                    g = _g_i1power(gpar[t, 0], gpar[t, 1], I1, Sk, coef)
                elif kind == 2:
                    g = _g_linear_i2(gpar[t, 0], I1, I2, C, Sk, coef)
                elif kind == 3:
                    g = _g_green_lagrange(gpar[t, 0], gpar[t, 1], C, Sk, coef)
                elif kind == 4:
                    g = _g_fibre(gpar, t, gmat, e if per_cell_R else 0, C, Sk, coef, W1, W2)
                else:
                    g = _g_eigen_power(gpar[t, 0], gpar[t, 1], gpar[t, 2], lam, V, Sk, theta_k, lp3,
                                       want_stiffness)
                u += f * g
                hg += df * g
                g2g += d2f * g
                if stressed:
                    has_S = True
                    if df != 0.0:
                        has_Sh = True
                    for i in range(3):
                        for j in range(3):
                            Sg[i, j] += f * Sk[i, j]
                            Shg[i, j] += df * Sk[i, j]
                for pr in range(npair[t]):
                    s = tslot[t, pr]
                    if slot_kind[s] == 2:
                        has_th = True
                        for i in range(3):
                            for j in range(3):
                                thg[i, j] += f * theta_k[i, j]
                    else:
                        wg[s] += f * coef[pr]
            if group_exp[grp] == 1:
                scale = group_coef[grp] * math.exp(u)
                e_cell += scale
                if want_stiffness:  # du_a = (F S_g + h_g cof) D_a
                    _matmul3(F, Sg, M3)
                    for i in range(3):
                        for j in range(3):
                            M3[i, j] += hg * cof[i, j]
                    apply_to_shape_vectors(M3, D, e, du[grp])
                escale[grp] = scale
            else:
                scale = group_coef[grp]
                e_cell += scale * u
                escale[grp] = 0.0
            h += scale * hg
            g2 += scale * g2g
            for i in range(3):
                for j in range(3):
                    St[i, j] += scale * Sg[i, j]
                    Sh[i, j] += scale * Shg[i, j]
                    th[i, j] += scale * thg[i, j]
            for s in range(nS):
                w[s] += scale * wg[s]
        vol = V0[e]
        energy += vol * e_cell
        if want_stress:
            _pk2(St, cof, J, h, stress_out, e)

        # ---- gradient: F S D_a + h d_a (F S formed once per cell)
        apply_to_shape_vectors(cof, D, e, d)
        if want_force:
            _matmul3(F, St, M3)
            for a in range(4):
                for i in range(3):
                    acc = h * d[a, i] + M3[i, 0] * D[e, a, 0] + M3[i, 1] * D[e, a, 1] + M3[i, 2] * D[e, a, 2]
                    force[cells[e, a], i] -= vol * acc
        if not want_stiffness:
            continue

        # ---- per-cell vectors of the edge blocks
        apply_to_shape_vectors(St, D, e, SD)  # S D_a, for the geometric term
        if has_Sh:
            _matmul3(F, Sh, M3)
            apply_to_shape_vectors(M3, D, e, FSh)
        for s in range(nS):
            if slot_kind[s] == 2 or w[s] == 0.0:
                continue
            me = e if per_cell_M else 0
            for a in range(4):
                for i in range(3):
                    if slot_ident[s] == 1:
                        MD[i] = D[e, a, i]
                    else:
                        MD[i] = slot_M[s, me, i, 0] * D[e, a, 0] + slot_M[s, me, i, 1] * D[e, a, 1] + slot_M[s, me, i, 2] * D[e, a, 2]
                for i in range(3):
                    Gs[s, a, i] = F[i, 0] * MD[0] + F[i, 1] * MD[1] + F[i, 2] * MD[2]
            if slot_kind[s] == 1:  # F M F^T
                for i in range(3):
                    for j in range(3):
                        acc = 0.0
                        for k in range(3):
                            for l in range(3):
                                acc += F[i, k] * slot_M[s, me, k, l] * F[j, l]
                        FMF[s, i, j] = acc
        if has_th:
            for n in range(3):
                for i in range(3):
                    wn[n, i] = F[i, 0] * V[0, n] + F[i, 1] * V[1, n] + F[i, 2] * V[2, n]
                for a in range(4):
                    cn[n, a] = V[0, n] * D[e, a, 0] + V[1, n] * D[e, a, 1] + V[2, n] * D[e, a, 2]
        breg = 0.0
        if regularize:
            breg = min(max(1.0 - J, 0.0), 1.0)
        keep = 1.0 - breg

        # ---- the six edge blocks
        for k in range(6):
            a, b = _EA[k], _EB[k]
            diag = 0.0
            if has_S:  # geometric (D_a . S D_b) Id
                diag = D[e, a, 0] * SD[b, 0] + D[e, a, 1] * SD[b, 1] + D[e, a, 2] * SD[b, 2]
            for r in range(3):
                for c in range(3):
                    K[k, r, c] = 0.0
            for s in range(nS):
                ws = w[s]
                if slot_kind[s] == 2 or ws == 0.0:
                    continue
                if slot_kind[s] == 0:
                    for r in range(3):
                        for c in range(3):
                            K[k, r, c] += 2.0 * ws * Gs[s, a, r] * Gs[s, b, c]
                else:
                    dmd = ws * slot_DMD[s, e, k]
                    for r in range(3):
                        for c in range(3):
                            K[k, r, c] += ws * Gs[s, b, r] * Gs[s, a, c] + dmd * FMF[s, r, c]
            if has_th:
                for n in range(3):
                    rsum = 0.0
                    for l in range(3):
                        rsum += th[n, l] * cn[l, b] * cn[l, a]
                    for c in range(3):
                        y = 0.0
                        for l in range(3):
                            y += th[n, l] * cn[l, a] * wn[l, c]
                        y = cn[n, b] * y + rsum * wn[n, c]
                        for r in range(3):
                            K[k, r, c] += wn[n, r] * y
            if has_Sh or g2 != 0.0:
                gk = g2 * keep
                for r in range(3):
                    for c in range(3):
                        v = gk * d[b, c]
                        if has_Sh:
                            v += FSh[b, c]
                            K[k, r, c] += FSh[a, r] * d[b, c]
                        K[k, r, c] += d[a, r] * v
                if regularize and g2 != 0.0:
                    diag += g2 * breg * (d[a, 0] * d[b, 0] + d[a, 1] * d[b, 1] + d[a, 2] * d[b, 2])
            for grp in range(G):
                sc = escale[grp]
                if sc == 0.0:
                    continue
                for r in range(3):
                    for c in range(3):
                        K[k, r, c] += sc * keep * du[grp, a, r] * du[grp, b, c]
                if regularize:
                    diag += sc * breg * (du[grp, a, 0] * du[grp, b, 0] + du[grp, a, 1] * du[grp, b, 1]
                                         + du[grp, a, 2] * du[grp, b, 2])
            if h != 0.0:  # h d2J/dx_a dx_b: the skew matrix of h F (D_a x D_b)
                q0 = h * (F[0, 0] * DxD[e, k, 0] + F[0, 1] * DxD[e, k, 1] + F[0, 2] * DxD[e, k, 2])
                q1 = h * (F[1, 0] * DxD[e, k, 0] + F[1, 1] * DxD[e, k, 1] + F[1, 2] * DxD[e, k, 2])
                q2 = h * (F[2, 0] * DxD[e, k, 0] + F[2, 1] * DxD[e, k, 1] + F[2, 2] * DxD[e, k, 2])
                K[k, 0, 1] += q2
                K[k, 1, 0] -= q2
                K[k, 0, 2] -= q1
                K[k, 2, 0] += q1
                K[k, 1, 2] += q0
                K[k, 2, 1] -= q0
            for r in range(3):
                K[k, r, r] += diag
        add_edge_blocks(U, Dg, cells, cell_edges, cell_flip, e, K, vol, Kd, True)
    if want_stiffness:
        write_csr(U, Dg, src, blkptr, indptr, data)
    return energy
