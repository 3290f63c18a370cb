#!/usr/bin/env python3
# MISTAKE: second derivative of Arruda-Boyce's series d2W/dI1b2 = mu sum c_i N^(1-i) i (i-1)
# I1b^(i-2) typed with i^2 for i (i-1) (the i = 2..5 terms 2, 1.5, 4/3, 5/4 times too large):
# stiffness wrong in both states, force and energy right.
"""P1 tetrahedral hyperelastic engine, graphics style (F-based, "Dynamic Deformables" layout).

Per cell: rest edge matrix Dm, Dm^-1, V0 = det Dm / 6; F = Ds Dm^-1; the first Piola-Kirchhoff
stress P = dPsi/dF written in F; the 9 x 12 matrix dF/dx (vec(F) column-major:
vec index k + 3 l for F_kl); f_e = -V0 dF/dx^T vec(P), K_e = V0 dF/dx^T (dP/dF) dF/dx with
dP/dF a 9 x 9 matrix per cell. Isotropic invariant laws through I_C = tr(F^T F),
II_C = ||F^T F||_F^2 and J = det F (dJ/dF the cofactor matrix, its Hessian from the
cross-product matrices of F's columns); Ogden through the rotation-variant SVD of F and the
analytic eigensystem of dP/dF (scaling, twist and flip modes); Costa in F with the kit's
per-cell frame (columns fibre, sheet, normal).

usage: python ENGINE INPUT_DIR OUTPUT_DIR
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "coo"
WRITE_ENERGY = True


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


def parameters(model):
    return {k: REAL(v) for k, v in model["parameters"].items()}


# ------------------------------------------------------------------ vec(F) and tensor helpers


def vec(A):
    """Vec of (..., 3, 3) matrices, column-major: index k + 3 l holds A_kl."""
    return np.swapaxes(A, -1, -2).reshape(A.shape[:-2] + (9,))


def mat9(T):
    """(..., 3, 3, 3, 3) tensor T_ijkl = dP_ij / dF_kl as the 9 x 9 matrix in vec order."""
    return np.swapaxes(np.swapaxes(T, -4, -3), -2, -1).reshape(T.shape[:-4] + (9, 9))


def outer9(a, b):
    return a[..., :, None] * b[..., None, :]


def eye3(m):
    return np.broadcast_to(np.eye(3, dtype=REAL), (m, 3, 3))


def det3(F):
    return (
        F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
        - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
        + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0])
    )


def cross_matrix(v):
    """[v]x, so that [v]x w = v x w."""
    z = np.zeros_like(v[:, 0])
    return np.stack(
        [
            np.stack([z, -v[:, 2], v[:, 1]], -1),
            np.stack([v[:, 2], z, -v[:, 0]], -1),
            np.stack([-v[:, 1], v[:, 0], z], -1),
        ],
        -2,
    )


def cofactor(F):
    """dJ/dF: columns f1 x f2, f2 x f0, f0 x f1 of F's columns f0, f1, f2."""
    f0, f1, f2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    return np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], -1)


def hessian_J(F):
    """d2J/dF2 as a 9 x 9 matrix in vec order: 3 x 3 blocks (column a of the cofactor by
    column b of F) [[0, -[f2], [f1]], [[f2], 0, -[f0]], [-[f1], [f0], 0]].
    """
    m = F.shape[0]
    f0, f1, f2 = (cross_matrix(F[:, :, a]) for a in range(3))
    Z = np.zeros((m, 3, 3), dtype=REAL)
    rows = [[Z, -f2, f1], [f2, Z, -f0], [-f1, f0, Z]]
    return np.concatenate([np.concatenate(r, -1) for r in rows], -2)


# ------------------------------------------------------------------ invariant laws


def log_volumetric(J, k0):
    lnJ = np.log(J)
    return k0 / 2 * lnJ**2, k0 * lnJ / J, k0 * (1 - lnJ) / J**2


def isochoric_law(name, prm, I1b, I2b):
    """W(I1b, I2b) and its derivatives W1, W2, W11, W12, W22."""
    x = I1b - 3
    zero = np.zeros_like(x)
    W2 = W12 = W22 = zero
    W = zero
    if name == "MooneyRivlin":
        c1, c2 = prm["c1"], prm["c2"]
        W = c1 * x + c2 * (I2b - 3)
        W1, W11, W2 = c1 + zero, zero, c2 + zero
    elif name == "VerondaWestmann":
        c1, c2 = prm["c1"], prm["c2"]
        e = np.exp(c2 * x)
        W = c1 * (e - 1) - c1 * c2 / 2 * (I2b - 3)
        W1, W11, W2 = c1 * c2 * e, c1 * c2**2 * e, -c1 * c2 / 2 + zero
    elif name == "ArrudaBoyce":
        mu, N = prm["mu"], prm["N"]
        coef = (0.5, 1 / 20, 11 / 1050, 19 / 7000, 519 / 673750)
        W1, W11 = zero, zero
        for i, c in enumerate(coef, start=1):
            ci = mu * c * N ** (1 - i)
            W = W + ci * (I1b**i - 3.0**i)
            W1 = W1 + ci * i * I1b ** (i - 1)
            if i >= 2:
                W11 = W11 + ci * i * i * I1b ** (i - 2)
    elif name == "Yeoh":
        c10, c20, c30 = prm["c10"], prm["c20"], prm["c30"]
        W = c10 * x + c20 * x**2 + c30 * x**3
        W1 = c10 + 2 * c20 * x + 3 * c30 * x**2
        W11 = 2 * c20 + 6 * c30 * x
    elif name == "Gent":
        mu, Jm = prm["mu"], prm["Jm"]
        t = 1 - x / Jm
        W = -mu * Jm / 2 * np.log(t)
        W1 = mu / 2 / t
        W11 = mu / (2 * Jm) / t**2
    elif name == "Demiray":
        a, b = prm["a"], prm["b"]
        e = np.exp(b * x)
        W = a / (2 * b) * (e - 1)
        W1 = a / 2 * e
        W11 = a * b / 2 * e
    else:
        raise ValueError(name)
    return W, W1, W2, W11, W12, W22


def invariant_law(name, prm, IC, IIC, J):
    """Psi(I_C, II_C, J), its gradient g (m, 3) and Hessian h (m, 3, 3) in (I_C, II_C, J)."""
    m = J.shape[0]
    g = np.zeros((m, 3), dtype=REAL)
    h = np.zeros((m, 3, 3), dtype=REAL)
    if name == "NeoHookean":
        mu, lam = prm["mu"], prm["lam"]
        lnJ = np.log(J)
        psi = mu / 2 * (IC - 3) - mu * lnJ + lam / 2 * lnJ**2
        g[:, 0] = mu / 2
        g[:, 2] = -mu / J + lam * lnJ / J
        h[:, 2, 2] = mu / J**2 + lam * (1 - lnJ) / J**2
        return psi, g, h
    if name == "StVenantKirchhoff":
        mu, lam = prm["mu"], prm["lam"]
        psi = lam / 8 * (IC - 3) ** 2 + mu / 4 * (IIC - 2 * IC + 3)
        g[:, 0] = lam / 4 * (IC - 3) - mu / 2
        g[:, 1] = mu / 4
        h[:, 0, 0] = lam / 4
        return psi, g, h
    # decoupled laws: W(I1b, I2b) + k0/2 (ln J)^2, I1b = J^(-2/3) I_C,
    # I2b = J^(-4/3) I2, I2 = (I_C^2 - II_C) / 2
    I2 = (IC**2 - IIC) / 2
    j23, j43 = J ** (-2 / 3), J ** (-4 / 3)
    I1b, I2b = j23 * IC, j43 * I2
    W, W1, W2, W11, W12, W22 = isochoric_law(name, prm, I1b, I2b)
    U, UJ, UJJ = log_volumetric(J, prm["k0"])
    psi = W + U
    # first derivatives of (I1b, I2b) in (I_C, II_C, J)
    d1 = np.zeros((m, 3), dtype=REAL)
    d2 = np.zeros((m, 3), dtype=REAL)
    d1[:, 0] = j23
    d1[:, 2] = -2 / 3 * j23 / J * IC
    d2[:, 0] = j43 * IC
    d2[:, 1] = -0.5 * j43
    d2[:, 2] = -4 / 3 * j43 / J * I2
    # second derivatives
    dd1 = np.zeros((m, 3, 3), dtype=REAL)
    dd2 = np.zeros((m, 3, 3), dtype=REAL)
    dd1[:, 0, 2] = dd1[:, 2, 0] = -2 / 3 * j23 / J
    dd1[:, 2, 2] = 10 / 9 * j23 / J**2 * IC
    dd2[:, 0, 0] = j43
    dd2[:, 0, 2] = dd2[:, 2, 0] = -4 / 3 * j43 / J * IC
    dd2[:, 1, 2] = dd2[:, 2, 1] = 2 / 3 * j43 / J
    dd2[:, 2, 2] = 28 / 9 * j43 / J**2 * I2
    g = W1[:, None] * d1 + W2[:, None] * d2
    g[:, 2] += UJ
    h = (
        W11[:, None, None] * outer9(d1, d1)
        + W12[:, None, None] * (outer9(d1, d2) + outer9(d2, d1))
        + W22[:, None, None] * outer9(d2, d2)
        + W1[:, None, None] * dd1
        + W2[:, None, None] * dd2
    )
    h[:, 2, 2] += UJJ
    return psi, g, h


def invariant_stress_and_hessian(name, prm, F):
    """P = sum_a Psi_a dI_a/dF, dP/dF = sum_ab Psi_ab vec(dI_a) vec(dI_b)^T + sum_a Psi_a H_a."""
    m = F.shape[0]
    C = np.einsum("nki,nkj->nij", F, F)
    B = np.einsum("nik,njk->nij", F, F)
    IC = np.einsum("nii->n", C)
    IIC = np.einsum("nij,nij->n", C, C)
    J = det3(F)
    psi, g, h = invariant_law(name, prm, IC, IIC, J)
    dIC = 2 * F
    dIIC = 4 * np.einsum("nik,nkj->nij", F, C)
    dJ = cofactor(F)
    P = g[:, 0, None, None] * dIC + g[:, 1, None, None] * dIIC + g[:, 2, None, None] * dJ
    grads = np.stack([vec(dIC), vec(dIIC), vec(dJ)], 1)  # (m, 3, 9)
    H = np.einsum("nab,nai,nbj->nij", h, grads, grads)
    I3 = np.eye(3, dtype=REAL)
    H_IC = 2 * np.eye(9, dtype=REAL)
    T = (
        np.einsum("ik,nlj->nijkl", I3, C)
        + np.einsum("nil,nkj->nijkl", F, F)
        + np.einsum("nik,jl->nijkl", B, I3)
    )
    H_IIC = 4 * mat9(T)
    H = H + g[:, 0, None, None] * H_IC + g[:, 1, None, None] * H_IIC
    H = H + g[:, 2, None, None] * hessian_J(F)
    del m
    return psi, P, H


# ------------------------------------------------------------------ Ogden through the SVD


def rotation_variant_svd(F):
    U, s, Vt = np.linalg.svd(F)
    V = np.swapaxes(Vt, -1, -2).copy()
    U = U.copy()
    s = s.copy()
    fu = np.linalg.det(U) < 0
    U[fu, :, 2] *= -1
    s[fu, 2] *= -1
    fv = np.linalg.det(V) < 0
    V[fv, :, 2] *= -1
    s[fv, 2] *= -1
    return U, s, V


def divided_power(si, sj, p):
    """(si^p - sj^p) / (si - sj), stable where si -> sj (limit p sj^(p-1))."""
    d = np.log(si) - np.log(sj)
    small = np.abs(d) < 1e-8
    ds = np.where(small, 1.0, d)
    r = np.where(small, p, np.expm1(p * ds) / np.expm1(ds))
    return sj ** (p - 1) * r


def ogden_principal(prm, s):
    """Psi(sigma), dPsi/dsigma_i and the 3 x 3 Hessian in sigma; c and g of
    dPsi/dsigma_i = c sigma_i^(alpha-1) - g / sigma_i.
    """
    mu, al, k0 = prm["mu"], prm["alpha"], prm["k0"]
    J = s[:, 0] * s[:, 1] * s[:, 2]
    lnJ = np.log(J)
    S = np.sum(s**al, 1)
    c = mu / al * J ** (-al / 3)
    g = c * S / 3 - k0 * lnJ
    psi = mu / al**2 * (J ** (-al / 3) * S - 3) + k0 / 2 * lnJ**2
    dpsi = c[:, None] * s ** (al - 1) - g[:, None] / s
    dc = -al / 3 * c[:, None] / s  # dc / dsigma_j
    dg = -al / 9 * (c * S)[:, None] / s + al / 3 * c[:, None] * s ** (al - 1) - k0 / s
    A = dc[:, None, :] * (s ** (al - 1))[:, :, None] - dg[:, None, :] / s[:, :, None]
    diag = c[:, None] * (al - 1) * s ** (al - 2) + g[:, None] / s**2
    A = A + diag[:, :, None] * np.eye(3, dtype=REAL)
    return psi, dpsi, A, c, g


PAIRS = ((0, 1), (1, 2), (0, 2))


def ogden_stress_and_hessian(prm, F):
    m = F.shape[0]
    U, s, V = rotation_variant_svd(F)
    psi, dpsi, A, c, g = ogden_principal(prm, s)
    al = prm["alpha"]
    P = np.einsum("nik,nk,njk->nij", U, dpsi, V)
    H = np.zeros((m, 9, 9), dtype=REAL)
    # scaling modes: eigenvectors of the 3 x 3 Hessian in sigma
    lam, w = np.linalg.eigh(A)
    for k in range(3):
        Q = np.einsum("nik,nk,njk->nij", U, w[:, :, k], V)
        q = vec(Q)
        H += lam[:, k, None, None] * outer9(q, q)
    # twist and flip modes of each pair
    for i, j in PAIRS:
        si, sj = s[:, i], s[:, j]
        twist = (dpsi[:, i] + dpsi[:, j]) / (si + sj)
        flip = c * divided_power(si, sj, al - 1) + g / (si * sj)
        ui, uj, vi, vj = U[:, :, i], U[:, :, j], V[:, :, i], V[:, :, j]
        Ut = (outer9(ui, vj) - outer9(uj, vi)) / np.sqrt(REAL(2))
        Uf = (outer9(ui, vj) + outer9(uj, vi)) / np.sqrt(REAL(2))
        for lam_k, Q in ((twist, Ut), (flip, Uf)):
            q = vec(Q)
            H += lam_k[:, None, None] * outer9(q, q)
    return psi, P, H


# ------------------------------------------------------------------ Costa in F


COSTA_B = (("b_ff", "b_fs", "b_fn"), ("b_fs", "b_ss", "b_sn"), ("b_fn", "b_sn", "b_nn"))


def costa_stress_and_hessian(prm, F, frame):
    m = F.shape[0]
    Bm = np.array([[prm[n] for n in row] for row in COSTA_B], dtype=REAL)
    r = [frame[:, :, i] for i in range(3)]  # fibre, sheet, normal: the frame's columns
    a = [np.einsum("nij,nj->ni", F, r[i]) for i in range(3)]  # I4-like: a_i = F r_i
    Q = np.zeros(m, dtype=REAL)
    dQ = np.zeros((m, 9), dtype=REAL)
    d2Q = np.zeros((m, 9, 9), dtype=REAL)
    for i in range(3):
        for j in range(3):
            Eij = (np.einsum("ni,ni->n", a[i], a[j]) - (i == j)) / 2  # Ef = R^T E R
            G = vec((outer9(a[i], r[j]) + outer9(a[j], r[i])) / 2)  # dEf_ij / dF
            N = (outer9(r[i], r[j]) + outer9(r[j], r[i])) / 2
            HE = mat9(np.einsum("ik,nlj->nijkl", np.eye(3, dtype=REAL), N))  # d2Ef_ij / dF2
            Q += Bm[i, j] * Eij**2
            dQ += 2 * Bm[i, j] * Eij[:, None] * G
            d2Q += 2 * Bm[i, j] * (outer9(G, G) + Eij[:, None, None] * HE)
    J = det3(F)
    cof = vec(cofactor(F))
    HJ = hessian_J(F)
    j43 = J ** (-4 / 3)
    q = j43 * Q
    dq = j43[:, None] * dQ - 4 / 3 * (q / J)[:, None] * cof
    d2q = (
        j43[:, None, None] * d2Q
        - 4 / 3 * (j43 / J)[:, None, None] * (outer9(dQ, cof) + outer9(cof, dQ))
        + 28 / 9 * (q / J**2)[:, None, None] * outer9(cof, cof)
        - 4 / 3 * (q / J)[:, None, None] * HJ
    )
    aa, k0 = prm["a"], prm["k0"]
    e = np.exp(q)
    lnJ = np.log(J)
    psi = aa / 2 * np.expm1(q) + k0 * (J * lnJ - J + 1)
    Pv = (aa / 2 * e)[:, None] * dq + (k0 * lnJ)[:, None] * cof
    H = (aa / 2 * e)[:, None, None] * (outer9(dq, dq) + d2q)
    H = H + (k0 / J)[:, None, None] * outer9(cof, cof) + (k0 * lnJ)[:, None, None] * HJ
    P = np.swapaxes(Pv.reshape(m, 3, 3), -1, -2)
    return psi, P, H


# ------------------------------------------------------------------ element and assembly


def stress_and_hessian(name, prm, F, arrays):
    if name == "Ogden":
        return ogden_stress_and_hessian(prm, F)
    if name == "Costa":
        return costa_stress_and_hessian(prm, F, arrays["frame"].astype(REAL))
    return invariant_stress_and_hessian(name, prm, F)


def edge_matrix(x, cells):
    return np.stack([x[cells[:, a]] - x[cells[:, 0]] for a in (1, 2, 3)], -1)


def dF_dx(Dm_inv):
    """9 x 12 per cell: dF_kl / dx_(a, c) = delta_kc G_al, G_a = row a-1 of Dm^-1 (a >= 1),
    G_0 = -(G_1 + G_2 + G_3); column 3 a + c, row k + 3 l (column-major vec(F)).
    """
    m = Dm_inv.shape[0]
    G = np.concatenate([-Dm_inv.sum(1, keepdims=True), Dm_inv], 1)  # (m, 4, 3)
    I3 = np.eye(3, dtype=REAL)
    T = np.einsum("kc,nal->nlkac", I3, G)  # row (l, k) -> k + 3 l
    return T.reshape(m, 9, 12)


def solve(case, arrays):
    name = case["model"]["name"]
    prm = parameters(case["model"])
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n, m = X.shape[0], cells.shape[0]
    Dm = edge_matrix(X, cells)
    Dm_inv = np.linalg.inv(Dm)
    V0 = det3(Dm) / 6
    Ds = edge_matrix(x, cells)
    F = np.einsum("nij,njk->nik", Ds, Dm_inv)
    psi, P, H = stress_and_hessian(name, prm, F, arrays)
    dFdx = dF_dx(Dm_inv)
    fe = -V0[:, None] * np.einsum("nai,na->ni", dFdx, vec(P))
    Ke = V0[:, None, None] * np.einsum("nai,nab,nbj->nij", dFdx, H, dFdx)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, fe)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    energy = np.sum(V0 * psi) if WRITE_ENERGY else None
    return force.reshape(n, 3), (rows, cols, Ke.ravel(), 3 * n), energy


def write(out, force, stiffness, energy):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ext = ".f32" if REAL == np.float32 else ".f64"
    fmt = "<f4" if REAL == np.float32 else "<f8"
    force.astype(fmt).tofile(out / f"force{ext}")
    rows, cols, vals, size = stiffness
    if LAYOUT == "coo":
        rows.astype("<i8").tofile(out / "stiffness_rows.i64")
        cols.astype("<i8").tofile(out / "stiffness_cols.i64")
        vals.astype(fmt).tofile(out / f"stiffness_values{ext}")
    else:
        K = sp.coo_matrix((vals, (rows, cols)), shape=(size, size)).tocsr()
        K.sum_duplicates()
        if LAYOUT == "csr":
            K.indptr.astype("<i8").tofile(out / "stiffness_indptr.i64")
            K.indices.astype("<i8").tofile(out / "stiffness_indices.i64")
            K.data.astype(fmt).tofile(out / f"stiffness_values{ext}")
        else:
            K.toarray().astype(fmt).tofile(out / f"stiffness{ext}")
    if energy is not None:
        np.array([energy]).astype(fmt).tofile(out / f"energy{ext}")


def main(argv):
    case, arrays = read_case(argv[1])
    force, stiffness, energy = solve(case, arrays)
    write(argv[2], force, stiffness, energy)


if __name__ == "__main__":
    main(sys.argv)
