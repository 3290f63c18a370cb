"""Numba kernels of the classical Total Lagrangian Galerkin (the paper's "standard FEM").

Per cell, as :mod:`reference_fem.classical` does with NumPy: F, C, J, C^-1; the law gives
W, S (Voigt 6) and the 6x6 elasticity tensor CC; B (6 x 12) the Green-Lagrange strain rate;
f_a = -V0 F S D_a; K_ab = V0 (B_a^T CC B_b + (D_a . S D_b) Id) for a <= b (K_ba = K_ab^T),
scattered into the CSR data array of mjed.sparse.CSRPattern. The laws are the formulas of
:mod:`reference_fem.classical_materials` (Holzapfel's invariant and decoupled forms, the
spectral form for Ogden, the fibre-frame quadratic for Costa), selected by the integer code
:mod:`reference_fem.classical_compiled` gives each law type.

On the same footing as the generated MJED kernels (mjed.compiled.codegen): the cell loop is
compiled once per law (a generated caller passes the law's code as a constant, see
:func:`kernel_source`, so the other laws' branches are not in it), with the same compiler
options, its scratch arrays on the stack (mjed.compiled.scratch), the same Jacobi
eigen-solver, V0 applied once per row of CC rather than per entry of K, and the same assembly
(edge and node sums, one ordered write of the CSR data). The isochoric projection of the
decoupled laws is applied as the rank-one update it is. What it does not get is the MJED
generator's dropping of structurally zero terms (its element matrix B^T CC B is dense
whatever the law) nor its scalar locals. Forming the node blocks as upper triangles, as the
MJED kernel does, made it slower here (the loop bounds then vary, 7.96 -> 8.95 ms for
St Venant-Kirchhoff), so it forms all nine entries.

Importing this module imports Numba. Serial, like the compiled MJED kernel.
"""

from __future__ import annotations

import math

import numpy as np
from numba import literally, njit

from mjed.compiled.kernels import JIT_OPTIONS, add_edge_block, apply_to_shape_vectors, deformation_gradient, eigh3, write_csr
from mjed.compiled.scratch import local_matrix, local_vector

__all__ = ["cells_for_law", "kernel_source", "LAW_SVK", "LAW_NEOHOOKE", "LAW_DECOUPLED", "LAW_OGDEN", "LAW_COSTA"]

_JIT = JIT_OPTIONS  # the MJED kernels' options

LAW_SVK, LAW_NEOHOOKE, LAW_DECOUPLED, LAW_OGDEN, LAW_COSTA = 0, 1, 2, 3, 4
PSI_MOONEY, PSI_VERONDA, PSI_ARRUDA = 0, 1, 2

_VI = np.array([0, 1, 2, 0, 1, 0])
_VJ = np.array([0, 1, 2, 1, 2, 2])
_WEIGHT = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
_IV = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
_II = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])  # diagonal of the symmetric identity (Voigt)


@njit(**_JIT)
def _odot(Ci, out):
    """(Ci (.) Ci)_IJ = (A_ik A_jl + A_il A_jk)/2, (6, 6)."""
    for I in range(6):
        i, j = _VI[I], _VJ[I]
        for J in range(6):
            k, l = _VI[J], _VJ[J]
            out[I, J] = 0.5 * (Ci[i, k] * Ci[j, l] + Ci[i, l] * Ci[j, k])


@njit(**_JIT)
def _volumetric(J, dU, ddU, ci, odot, S, CC, tangent):
    """Adds S_vol = J U' C^-1 and (if tangent) CC_vol = J (U' + J U'') ci (x) ci - 2 J U' C^-1 (.) C^-1."""
    a = J * (dU + J * ddU)
    b = 2.0 * J * dU
    for I in range(6):
        S[I] += J * dU * ci[I]
        if not tangent:
            continue
        for K in range(6):
            CC[I, K] += a * ci[I] * ci[K] - b * odot[I, K]


@njit(**_JIT)
def _psi(kind, P, I1b, I2b):
    """Psi(I1b, I2b) and Psi_1, Psi_2, Psi_11, Psi_12, Psi_22 of the decoupled laws."""
    if kind == PSI_MOONEY:
        c1, c2 = P[1], P[2]
        return c1 * (I1b - 3.0) + c2 * (I2b - 3.0), c1, c2, 0.0, 0.0, 0.0
    if kind == PSI_VERONDA:
        c1, c2 = P[1], P[2]
        ex = math.exp(c2 * (I1b - 3.0))
        return c1 * (ex - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0), c1 * c2 * ex, -0.5 * c1 * c2, c1 * c2 * c2 * ex, 0.0, 0.0
    W = 0.0  # Arruda-Boyce: sum_i a_i (I1b^i - 3^i), a_i = P[1 + i]
    p1 = 0.0
    p11 = 0.0
    for i in range(1, 6):
        a = P[1 + i]
        W += a * (I1b ** i - 3.0 ** i)
        p1 += i * a * I1b ** (i - 1)
        if i > 1:
            p11 += i * (i - 1) * a * I1b ** (i - 2)
    return W, p1, 0.0, p11, 0.0, 0.0


@njit(**_JIT)
def _law(code, psi, P, T, C, Ci, J, S, CC, odot, W6, M66, N66, lam, N, sc, cv, cbv, Siso, M, H, tangent):
    """W of the law; fills S (6,) and, if ``tangent``, CC (6, 6) (a force-only evaluation skips
    the elasticity tensor, as the NumPy law does). P: parameters; T: Costa's (6, 6) tensor.
    Scratch (kept by the caller, so nothing is allocated per cell): W6, cv, cbv, Siso (6,);
    M66, N66 (6, 6); lam (3,); N, sc, H (3, 3); M (6, 3)."""
    for I in range(6):
        S[I] = 0.0
        if tangent:
            for K in range(6):
                CC[I, K] = 0.0
    lnJ = math.log(J)
    ci = W6
    for I in range(6):
        ci[I] = Ci[_VI[I], _VJ[I]]
    if code == LAW_SVK:
        mu, lm = P[0], P[1]
        trE = 0.5 * (C[0, 0] + C[1, 1] + C[2, 2]) - 1.5
        EE = 0.0
        for i in range(3):
            for j in range(3):
                Eij = 0.5 * (C[i, j] - (1.0 if i == j else 0.0))
                EE += Eij * Eij
        for I in range(6):
            S[I] = 2.0 * mu * 0.5 * (C[_VI[I], _VJ[I]] - _IV[I]) + lm * trE * _IV[I]
            if not tangent:
                continue
            CC[I, I] += 2.0 * mu * _II[I]
            for K in range(6):
                CC[I, K] += lm * _IV[I] * _IV[K]
        return 0.5 * lm * trE * trE + mu * EE
    if tangent:
        _odot(Ci, odot)
    if code == LAW_NEOHOOKE:
        mu, lm = P[0], P[1]
        a = lm * lnJ - mu
        b = 2.0 * (mu - lm * lnJ)
        for I in range(6):
            S[I] = a * ci[I] + mu * _IV[I]
            if not tangent:
                continue
            for K in range(6):
                CC[I, K] = lm * ci[I] * ci[K] + b * odot[I, K]
        I1 = C[0, 0] + C[1, 1] + C[2, 2]
        return 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * lm * lnJ * lnJ
    if code == LAW_DECOUPLED:
        k0 = P[0]
        I1 = C[0, 0] + C[1, 1] + C[2, 2]
        CCs = 0.0
        for i in range(3):
            for j in range(3):
                CCs += C[i, j] * C[j, i]
        I2 = 0.5 * (I1 * I1 - CCs)
        j23 = J ** (-2.0 / 3.0)
        I1b, I2b = j23 * I1, j23 * j23 * I2
        psi_v, p1, p2, p11, p12, p22 = _psi(psi, P, I1b, I2b)
        # Sb, then S_iso = j23 Sb - tr/3 ci, tr = j23 Sb : C (sc[0] holds cv, sc[1] cbv / S_iso halves)
        tr = 0.0
        for I in range(6):
            cv[I] = C[_VI[I], _VJ[I]]
            cbv[I] = j23 * cv[I]
            Sb = -2.0 * p2 * cbv[I] + 2.0 * (p1 + I1b * p2) * _IV[I]
            Siso[I] = j23 * Sb
            tr += _WEIGHT[I] * Siso[I] * cv[I]
        for I in range(6):
            Siso[I] -= tr / 3.0 * ci[I]
            S[I] = Siso[I]
        if not tangent:
            _volumetric(J, k0 * lnJ / J, k0 * (1.0 - lnJ) / (J * J), ci, odot, S, CC, False)
            return psi_v + 0.5 * k0 * lnJ * lnJ
        j43 = j23 * j23
        a = 4.0 * (p11 + 2.0 * I1b * p12 + p2 + I1b * I1b * p22)
        b = -4.0 * (p12 + I1b * p22)
        for I in range(6):  # M66 = CCb
            for K in range(6):
                M66[I, K] = j43 * (a * _IV[I] * _IV[K] + b * (_IV[I] * cbv[K] + cbv[I] * _IV[K])
                                   + 4.0 * p22 * cbv[I] * cbv[K])
            M66[I, I] -= j43 * 4.0 * p2 * _II[I]
        # Pw = Id - ci (x) w, w = (cv W) / 3, is a rank-one update: N66 = Pw CCb = CCb - ci (x) (w CCb)
        # and N66 Pw^T = N66 - (N66 w) (x) ci, O(36) each instead of a 6x6x6 product.
        # Scratch: M[:, 0] = w, M[:, 1] = w CCb, M[:, 2] = N66 w (M is Ogden's, unused here).
        for L in range(6):
            M[L, 0] = cv[L] * _WEIGHT[L] / 3.0
        for K in range(6):
            acc = 0.0
            for L in range(6):
                acc += M[L, 0] * M66[L, K]
            M[K, 1] = acc
        for I in range(6):
            acc = 0.0
            for K in range(6):
                N66[I, K] = M66[I, K] - ci[I] * M[K, 1]
                acc += N66[I, K] * M[K, 0]
            M[I, 2] = acc
        for I in range(6):  # CC = N66 Pw^T + ...
            for K in range(6):
                CC[I, K] = (N66[I, K] - M[I, 2] * ci[K] + 2.0 / 3.0 * tr * (odot[I, K] - ci[I] * ci[K] / 3.0)
                            - 2.0 / 3.0 * (ci[I] * Siso[K] + Siso[I] * ci[K]))
        _volumetric(J, k0 * lnJ / J, k0 * (1.0 - lnJ) / (J * J), ci, odot, S, CC, True)
        return psi_v + 0.5 * k0 * lnJ * lnJ
    if code == LAW_OGDEN:
        c, q, r, alpha, k0 = P[0], P[1], P[2], P[3], P[4]
        eigh3(C, lam, N, sc)
        Pj = J ** (-alpha / 3.0)
        cP = c * Pj
        lq1 = cv  # (first 3 entries)
        sigma = 0.0
        for i in range(3):
            lq1[i] = lam[i] ** (q - 1.0)
            sigma += lq1[i] * lam[i]
        for I in range(6):
            acc = 0.0
            for i in range(3):
                M[I, i] = N[_VI[I], i] * N[_VJ[I], i]
                w = cP * (q * lq1[i] + r * sigma / lam[i])
                acc += M[I, i] * 2.0 * w
            S[I] = acc
        if not tangent:
            _volumetric(J, k0 * lnJ / J, k0 * (1.0 - lnJ) / (J * J), ci, odot, S, CC, False)
            return c * (Pj * sigma - 3.0) + 0.5 * k0 * lnJ * lnJ
        for i in range(3):
            for j in range(3):
                H[i, j] = r * (q * lq1[i] / lam[j] + q * lq1[j] / lam[i]) + r * r * sigma / (lam[i] * lam[j])
            H[i, i] += q * (q - 1.0) * lam[i] ** (q - 2.0) - r * sigma / (lam[i] * lam[i])
        for I in range(6):
            for K in range(6):
                acc = 0.0
                for i in range(3):
                    for j in range(3):
                        acc += M[I, i] * 4.0 * cP * H[i, j] * M[K, j]
                CC[I, K] = acc
        for pi in range(3):
            i, j = (0, 1) if pi == 0 else ((1, 2) if pi == 1 else (0, 2))
            t = math.log(lam[i] / lam[j])
            ratio = q - 1.0 if t == 0.0 else math.expm1((q - 1.0) * t) / math.expm1(t)
            dd = lam[j] ** (q - 2.0) * ratio
            theta = 2.0 * cP * (q * dd - r * sigma / (lam[i] * lam[j]))
            for I in range(6):
                W6_I = N[_VI[I], i] * N[_VJ[I], j] + N[_VI[I], j] * N[_VJ[I], i]
                for K in range(6):
                    GK = N[_VI[K], i] * N[_VJ[K], j] + N[_VI[K], j] * N[_VJ[K], i]
                    CC[I, K] += theta * W6_I * GK
        _volumetric(J, k0 * lnJ / J, k0 * (1.0 - lnJ) / (J * J), ci, odot, S, CC, True)
        return c * (Pj * sigma - 3.0) + 0.5 * k0 * lnJ * lnJ
    # LAW_COSTA
    a_, k0 = P[0], P[1]
    e_eng = cv
    qv = cbv
    for I in range(6):
        e_eng[I] = 0.5 * (C[_VI[I], _VJ[I]] - _IV[I]) * _WEIGHT[I]
    Q = 0.0
    for I in range(6):
        acc = 0.0
        for K in range(6):
            acc += T[I, K] * e_eng[K]
        qv[I] = acc
        Q += 0.5 * e_eng[I] * acc
    j43 = J ** (-4.0 / 3.0)
    ex = 0.5 * a_ * math.exp(j43 * Q)
    pQ = ex * j43
    pJ = -4.0 / 3.0 * ex * Q * j43 / J + k0 * lnJ
    pQQ = ex * j43 * j43
    pQJ = -4.0 / 3.0 * ex * j43 / J * (1.0 + j43 * Q)
    pJJ = ex * (16.0 / 9.0 * Q * Q * j43 * j43 + 28.0 / 9.0 * Q * j43) / (J * J) + k0 / J
    for I in range(6):
        S[I] = pQ * qv[I] + J * pJ * ci[I]
        if not tangent:
            continue
        for K in range(6):
            CC[I, K] = (pQQ * qv[I] * qv[K] + J * pQJ * (qv[I] * ci[K] + ci[I] * qv[K]) + pQ * T[I, K]
                        + J * (J * pJJ + pJ) * ci[I] * ci[K] - 2.0 * J * pJ * odot[I, K])
    return 0.5 * a_ * math.expm1(j43 * Q) + k0 * (J * lnJ - J + 1.0)


@njit(**_JIT)
def cells_for_law(code, psi, x, cells, D, V0, P, Tt, want_force, want_stiffness, cell_edges, cell_flip, U, Dg, src,
                    blkptr, indptr, force, data, J_out):
    """Energy, forces (added to ``force``) and stiffness (written to ``data``) of every cell by
    the classical Galerkin; J per cell into J_out. code, psi: the law and (decoupled laws) the
    isochoric part, as reference_fem.classical_compiled lowers them, given as constants by the
    generated caller (:func:`kernel_source`): the loop is compiled once per (code, psi)
    (``literally``), so the branches of the other laws are not in it, as the generated MJED
    kernel holds only its material's terms. Tt: Costa's tensor
    (1 or m, 6, 6). The assembly is the MJED kernels' (edge blocks summed per mesh edge, node
    blocks per node, then one ordered write of the CSR data: mjed.compiled.kernels.write_csr),
    except that the node blocks are the element's own K_aa, not derived. Scratch arrays live on the stack (mjed.compiled.scratch). Returns the total
    energy."""
    literally(code)
    literally(psi)
    m = cells.shape[0]
    per_cell_T = Tt.shape[0] > 1
    F = local_matrix(3, 3)
    C = local_matrix(3, 3)
    Ci = local_matrix(3, 3)
    S = local_vector(6)
    CC = local_matrix(6, 6)
    odot = local_matrix(6, 6)
    W6 = local_vector(6)
    M66 = local_matrix(6, 6)
    N66 = local_matrix(6, 6)
    lam = local_vector(3)
    N = local_matrix(3, 3)
    sc = local_matrix(3, 3)
    B = local_matrix(6, 12)
    CB = local_matrix(6, 12)
    Sm = local_matrix(3, 3)
    SD = local_matrix(4, 3)
    Kab = local_matrix(3, 3)
    cv = local_vector(6)
    cbv = local_vector(6)
    Siso = local_vector(6)
    M63 = local_matrix(6, 3)
    H3 = local_matrix(3, 3)
    if want_stiffness:
        U[:] = 0.0
        Dg[:] = 0.0
    energy = 0.0
    for e in range(m):
        deformation_gradient(x, cells, D, e, F)
        J = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
             + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
        J_out[e] = J
        for i in range(3):
            for j in range(3):
                C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
        det = J * J  # C^-1 by the adjugate
        Ci[0, 0] = (C[1, 1] * C[2, 2] - C[1, 2] * C[2, 1]) / det
        Ci[1, 1] = (C[0, 0] * C[2, 2] - C[0, 2] * C[2, 0]) / det
        Ci[2, 2] = (C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]) / det
        Ci[0, 1] = Ci[1, 0] = (C[0, 2] * C[2, 1] - C[0, 1] * C[2, 2]) / det
        Ci[1, 2] = Ci[2, 1] = (C[0, 2] * C[1, 0] - C[0, 0] * C[1, 2]) / det
        Ci[0, 2] = Ci[2, 0] = (C[0, 1] * C[1, 2] - C[0, 2] * C[1, 1]) / det
        Te = Tt[e] if per_cell_T else Tt[0]
        W = _law(code, psi, P, Te, C, Ci, J, S, CC, odot, W6, M66, N66, lam, N, sc, cv, cbv, Siso, M63, H3,
                 want_stiffness)
        vol = V0[e]
        energy += vol * W
        for I in range(6):
            Sm[_VI[I], _VJ[I]] = S[I]
            Sm[_VJ[I], _VI[I]] = S[I]
        apply_to_shape_vectors(Sm, D, e, SD)
        if want_force:  # f_a = -V0 F S D_a
            for a in range(4):
                for k in range(3):
                    force[cells[e, a], k] -= vol * (F[k, 0] * SD[a, 0] + F[k, 1] * SD[a, 1] + F[k, 2] * SD[a, 2])
        if not want_stiffness:
            continue
        for I in range(6):  # B[I, 3a + k] = D_a,j F_k,i + D_a,i F_k,j (halved on the diagonal)
            i, j = _VI[I], _VJ[I]
            half = 0.5 if I < 3 else 1.0
            for a in range(4):
                for k in range(3):
                    B[I, 3 * a + k] = half * (D[e, a, j] * F[k, i] + D[e, a, i] * F[k, j])
        for I in range(6):  # CB = V0 CC B: V0 applied once per row of CC, not per entry of K
            for L in range(6):
                CC[I, L] *= vol
            for col in range(12):
                acc = 0.0
                for L in range(6):
                    acc += CC[I, L] * B[L, col]
                CB[I, col] = acc
        edge = 0
        for a in range(4):
            for b in range(a, 4):
                geo = vol * (D[e, a, 0] * SD[b, 0] + D[e, a, 1] * SD[b, 1] + D[e, a, 2] * SD[b, 2])
                for k in range(3):
                    for l in range(3):
                        acc = geo if k == l else 0.0
                        for I in range(6):
                            acc += B[I, 3 * a + k] * CB[I, 3 * b + l]
                        Kab[k, l] = acc
                if a == b:
                    na = cells[e, a]
                    for k in range(3):
                        for l in range(3):
                            Dg[na, k, l] += Kab[k, l]
                else:  # (a, b) in mjed.sparse.EDGES order: (0,1) (0,2) (0,3) (1,2) (1,3) (2,3)
                    add_edge_block(U, cell_edges[e, edge], cell_flip[e, edge], Kab)
                    edge += 1
    if want_stiffness:
        write_csr(U, Dg, src, blkptr, indptr, data)
    return energy


def kernel_source(code: int, psi: int) -> str:
    """Source of a module whose ``classical_cells`` (the arguments of :func:`cells_for_law`
    without code and psi) runs the loop compiled for law ``code`` and isochoric part ``psi``.
    Loaded by mjed.compiled.specialise.generated_module, as the MJED kernels are: calling
    cells_for_law with constants resolves ``literally`` at compile time, once."""
    args = ("x, cells, D, V0, P, Tt, want_force, want_stiffness, cell_edges, cell_flip, U, Dg, src, blkptr, indptr, "
            "force, data, J_out")
    return (f'''"""Classical Galerkin kernel for law {int(code)}, isochoric part {int(psi)}; generated by
reference_fem.classical_kernels.kernel_source, do not edit."""
from numba import njit

from reference_fem.classical_kernels import JIT_OPTIONS, cells_for_law


@njit(**JIT_OPTIONS)
def classical_cells({args}):
    return cells_for_law({int(code)}, {int(psi)}, {args})
''')
