"""The kernels of the viscous and the porous models on the device
(:mod:`mjed.cuda.device_models`), hand-written, FP64.

Each is the device form of a vectorised NumPy computation of the host model, same
equations:

- the Prony history (:mod:`mjed.viscous`): Q = sum_i b_i gamma_i per cell
  (:func:`prony_stress`); the constant stress's stiffness, blocks -V (D_a . Q D_b) Id added
  into the CSR values, and its force -sum_b s_ab x_b (:func:`history_force_stiffness`);
  gamma_i^n = a_i S_h + b_i gamma_i^(n-1) after an accepted step (:func:`prony_update`);
- the fluid pressure's coupling (:mod:`mjed.darcy`, :class:`mjed.darcy.FluidPressureForce`):
  the energy V (U(J) - Pbar (J - 1)) per cell, U the porous solid
  (:class:`mjed.porous.PorousVolume`) or none, its force -V (U' - Pbar) cof(F) D_a and its
  stiffness V (U'' g_a (x) g_b + (U' - Pbar) d2J/dx_a dx_b), g_a = cof(F) D_a and
  d2J/dx_a dx_b = [F (D_a x D_b)]_x (:func:`fluid_force_stiffness`);
- the Darcy step (:class:`mjed.darcy.PressureSolver`): the source V/4 ln(J_new / J_old) per
  cell and node (:func:`darcy_source`), the right-hand side (M P) / K_lim - s on the free
  nodes (:func:`darcy_rhs`) and the matrix M / K_lim + dt kappa L with the drained rows and
  columns of the identity (:func:`darcy_matrix`), solved by the device CG.

Every kernel is a grid-stride loop (:mod:`mjed.cuda.threads`; one cell, row or entry a
thread on a GPU). Cell kernels add into shared nodes and CSR values by atomics,
through the field's block map (:func:`mjed.cuda.codegen.block_map`: entry (r, c) of block
(a, b) of cell e at blk[e, 4 a + b] + r rowlen[node a] + c). Importing this module imports
numba.cuda.
"""

from __future__ import annotations

import math

from numba import cuda, float64

__all__ = [
    "cast_into",
    "darcy_matrix",
    "darcy_rhs",
    "darcy_source",
    "fluid_force_stiffness",
    "history_force_stiffness",
    "prony_stress",
    "prony_update",
    "scale_into",
]


@cuda.jit
def scale_into(src, c, dst):
    """Dst = c src (dst float64, src in any dtype), one thread per entry."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, dst.shape[0], stride):
        dst[i] = c * src[i]


@cuda.jit
def cast_into(src, dst):
    """Dst = src in dst's dtype (rounded as a host copy would be)."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, dst.shape[0], stride):
        dst[i] = src[i]


# ------------------------------------------------------------------------- the Prony history
@cuda.jit
def prony_stress(gammas, b, Q):
    """Q[e] = sum_i b_i gammas[i, e] (gammas (p, m, 3, 3)), one thread per cell."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for e in range(start, Q.shape[0], stride):
        for r in range(3):
            for c in range(3):
                s = 0.0
                for i in range(b.shape[0]):
                    s += b[i] * gammas[i, e, r, c]
                Q[e, r, c] = s


@cuda.jit
def prony_update(gammas, S, a, b, out):
    """Out[i, e] = a_i S[e] + b_i gammas[i, e] (S in the field's dtype), one thread per cell."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for e in range(start, S.shape[0], stride):
        for i in range(a.shape[0]):
            for r in range(3):
                for c in range(3):
                    out[i, e, r, c] = a[i] * S[e, r, c] + b[i] * gammas[i, e, r, c]


@cuda.jit
def history_force_stiffness(x0, ue, cells, D, V, Q, blk, rowlen, f, K):
    """The constant stress -Q of each cell: K += blocks s_ab Id, f_a -= sum_b s_ab x_b, with
    s_ab = -V (D_a . Q D_b) and x = x0 + ue (flat (3n,)); f (3n,) and K (nnz,) float64.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for e in range(start, cells.shape[0], stride):
        QD = cuda.local.array(12, float64)  # Q D_b, (3, 4)
        for k in range(3):
            for b in range(4):
                QD[4 * k + b] = (
                    Q[e, k, 0] * D[e, b, 0] + Q[e, k, 1] * D[e, b, 1] + (Q[e, k, 2] * D[e, b, 2])
                )
        v = V[e]
        for a in range(4):
            na = cells[e, a]
            length = rowlen[na]
            f0 = 0.0
            f1 = 0.0
            f2 = 0.0
            for b in range(4):
                nb = cells[e, b]
                s = -v * (D[e, a, 0] * QD[b] + D[e, a, 1] * QD[4 + b] + D[e, a, 2] * QD[8 + b])
                f0 += s * (x0[3 * nb] + ue[3 * nb])
                f1 += s * (x0[3 * nb + 1] + ue[3 * nb + 1])
                f2 += s * (x0[3 * nb + 2] + ue[3 * nb + 2])
                base = blk[e, 4 * a + b]
                for r in range(3):
                    cuda.atomic.add(K, base + r * length + r, s)
            cuda.atomic.add(f, 3 * na, -f0)
            cuda.atomic.add(f, 3 * na + 1, -f1)
            cuda.atomic.add(f, 3 * na + 2, -f2)


# ------------------------------------------------------------------------- the fluid's force
@cuda.jit(device=True)
def porous_derivatives(J, fw, K0, J0, s0, k0):
    """U'(J) and U''(J) of :class:`mjed.porous.PorousVolume` (s0 = U'(J0), k0 = U''(J0))."""
    if J > J0:
        return K0 * fw * math.log((fw + J - 1.0) / fw), K0 * fw / (fw + J - 1.0)
    return s0 + k0 * (J - J0), k0


@cuda.jit
def fluid_force_stiffness(
    x0, ue, cells, D, V, P, solid, fw, K0, J0, s0, k0, blk, rowlen, f, K
):  # fmt: skip
    """The energy V (U(J) - Pbar (J - 1)) of each cell (U = 0 unless ``solid``): its force
    into f (3n,) and its stiffness into K (nnz,), both float64; x = x0 + ue (flat (3n,)).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for e in range(start, cells.shape[0], stride):
        F = cuda.local.array(9, float64)
        for i in range(3):
            for j in range(3):
                s = 0.0
                for a in range(4):
                    q = 3 * cells[e, a] + i
                    s += (x0[q] + ue[q]) * D[e, a, j]
                F[3 * i + j] = s
        cof = cuda.local.array(9, float64)
        cof[0] = F[4] * F[8] - F[5] * F[7]
        cof[1] = F[5] * F[6] - F[3] * F[8]
        cof[2] = F[3] * F[7] - F[4] * F[6]
        cof[3] = F[2] * F[7] - F[1] * F[8]
        cof[4] = F[0] * F[8] - F[2] * F[6]
        cof[5] = F[1] * F[6] - F[0] * F[7]
        cof[6] = F[1] * F[5] - F[2] * F[4]
        cof[7] = F[2] * F[3] - F[0] * F[5]
        cof[8] = F[0] * F[4] - F[1] * F[3]
        J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2]
        pbar = 0.25 * (P[cells[e, 0]] + P[cells[e, 1]] + P[cells[e, 2]] + P[cells[e, 3]])
        sigma = -pbar
        slope = 0.0
        if solid:
            du, ddu = porous_derivatives(J, fw, K0, J0, s0, k0)
            sigma += du
            slope = ddu
        v = V[e]
        g = cuda.local.array(12, float64)  # g_a = cof(F) D_a = dJ/dx_a, (4, 3)
        for a in range(4):
            for i in range(3):
                g[3 * a + i] = (
                    cof[3 * i] * D[e, a, 0]
                    + cof[3 * i + 1] * D[e, a, 1]
                    + (cof[3 * i + 2] * D[e, a, 2])
                )
            na = cells[e, a]
            for i in range(3):
                cuda.atomic.add(f, 3 * na + i, -v * sigma * g[3 * a + i])
        for a in range(4):
            na = cells[e, a]
            length = rowlen[na]
            for b in range(4):
                # w = F (D_a x D_b): d2J/dx_a,i dx_b,j = eps_ijk w_k
                c0 = D[e, a, 1] * D[e, b, 2] - D[e, a, 2] * D[e, b, 1]
                c1 = D[e, a, 2] * D[e, b, 0] - D[e, a, 0] * D[e, b, 2]
                c2 = D[e, a, 0] * D[e, b, 1] - D[e, a, 1] * D[e, b, 0]
                w0 = F[0] * c0 + F[1] * c1 + F[2] * c2
                w1 = F[3] * c0 + F[4] * c1 + F[5] * c2
                w2 = F[6] * c0 + F[7] * c1 + F[8] * c2
                base = blk[e, 4 * a + b]
                for r in range(3):
                    for c in range(3):
                        h = 0.0
                        if r == 0 and c == 1:
                            h = w2
                        elif r == 0 and c == 2:
                            h = -w1
                        elif r == 1 and c == 0:
                            h = -w2
                        elif r == 1 and c == 2:
                            h = w0
                        elif r == 2 and c == 0:
                            h = w1
                        elif r == 2 and c == 1:
                            h = -w0
                        value = v * (slope * g[3 * a + r] * g[3 * b + c] + sigma * h)
                        cuda.atomic.add(K, base + r * length + c, value)


# ------------------------------------------------------------------------- the Darcy step
@cuda.jit
def darcy_source(cells, V, J_old, J_new, s, out):
    """S_i += V/4 ln(J_new / J_old) over the cells of node i (s zeroed before); out[0] += the
    cells whose J_old or J_new is not finite and > 0 (their source is left out: the host
    names them).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    bad = 0.0
    for e in range(start, cells.shape[0], stride):
        j0 = J_old[e]
        j1 = J_new[e]
        if j0 > 0.0 and j1 > 0.0 and math.isfinite(j0) and math.isfinite(j1):
            r = math.log(j1 / j0) * (V[e] / 4.0)
            for a in range(4):
                cuda.atomic.add(s, cells[e, a], r)
        else:
            bad += 1.0
    cuda.atomic.add(out, 0, bad)


@cuda.jit
def darcy_rhs(indptr, indices, mass, P, s, drained, K_lim, rhs, guess):
    """Rhs = (M P) / K_lim - s over the free nodes (the drained columns left out), 0 on the
    drained rows; guess = P there, 0 on the drained rows (the CG's first guess).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, rhs.shape[0], stride):
        if drained[i]:
            rhs[i] = 0.0
            guess[i] = 0.0
        else:
            acc = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                if not drained[j]:
                    acc += mass[k] * P[j]
            rhs[i] = acc / K_lim - s[i]
            guess[i] = P[i]


@cuda.jit
def darcy_matrix(indptr, indices, mass, laplacian, drained, K_lim, c, out):
    """Out = M / K_lim + c L on the free rows and columns (c = dt kappa); the drained rows and
    columns are the identity's.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, drained.shape[0], stride):
        di = drained[i]
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if di or drained[j]:
                out[k] = 1.0 if (di and j == i) else 0.0
            else:
                out[k] = mass[k] / K_lim + c * laplacian[k]
