#!/usr/bin/env python3
# MISTAKE: numerical DDSDDE with F perturbed as F + eps/2 (e_i e_j + e_j e_i) (not multiplied by F
# on the right: a material rather than spatial strain increment); forward differences of tau, eps
# = 1e-7.
"""UMAT-style hyperelastic engine (python ENGINE INPUT_DIR OUTPUT_DIR).

Each material is a ported Abaqus UMAT: vectorised over the cells, it takes DFGRD1 (F), its PROPS
(and, for Costa, the per-cell orientation) and returns STRESS, the Cauchy stress in Abaqus' Voigt
order (11, 22, 33, 12, 13, 23), DDSDDE, the Jaumann-rate tangent of the Kirchhoff stress divided
by J in that order (engineering shear strains), and SSE, the energy per rest volume. The driver
removes the Jaumann terms to get the Truesdell (Oldroyd) spatial tangent c, and assembles
f_a = -v sigma g_a and K_ab = v (g_a . c . g_b + (g_a . sigma g_b) I) with g_a = dN_a/dx.
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

LAYOUT = "csr"
DT = np.float64
SUFFIX = ".f64"
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # Abaqus: 11, 22, 33, 12, 13, 23
UNPACK = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the driver's map back to tensors


def eye(m):
    return np.broadcast_to(np.eye(3, dtype=DT), (m, 3, 3))


def dyad(a, b):
    return np.einsum("mij,mkl->mijkl", a, b)


def symdyad(a, b):
    return 0.5 * (np.einsum("mik,mjl->mijkl", a, b) + np.einsum("mil,mjk->mijkl", a, b))


def push2(F, S):
    return np.einsum("miI,mIJ,mjJ->mij", F, S, F)


def push4(F, CC):
    return np.einsum("miI,mjJ,mkK,mlL,mIJKL->mijkl", F, F, F, F, CC)


def rot2(R, X):
    return np.einsum("mia,mab,mjb->mij", R, X, R)


def rot4(R, X):
    return np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", R, R, R, R, X)


def dev4(X):
    """P : X : P with P = II - 1/3 I (x) I (X with minor symmetries)."""
    m = X.shape[0]
    d = np.eye(3, dtype=DT)
    t12 = np.einsum("mppkl->mkl", X)
    t34 = np.einsum("mijpp->mij", X)
    tt = np.einsum("mpp->m", t12)
    out = X - np.einsum("ij,mkl->mijkl", d, t12) / 3.0 - np.einsum("mij,kl->mijkl", t34, d) / 3.0
    return out + np.einsum("m,ij,kl->mijkl", tt, d, d) / 9.0 + 0.0 * m


def jaumann(sig):
    """1/2 (d_ik s_jl + d_il s_jk + d_jk s_il + d_jl s_ik)."""
    d = np.eye(3, dtype=DT)
    return 0.5 * (
        np.einsum("ik,mjl->mijkl", d, sig)
        + np.einsum("il,mjk->mijkl", d, sig)
        + np.einsum("jk,mil->mijkl", d, sig)
        + np.einsum("jl,mik->mijkl", d, sig)
    )


def umat_return(tau, Jc, J, W):
    """Kirchhoff stress and tangent -> STRESS, DDSDDE (Jaumann rate of tau, over J), SSE."""
    sig = tau / J[:, None, None]
    c = Jc / J[:, None, None, None, None]
    ddsdde = c + jaumann(sig)
    stress = np.stack([sig[:, i, j] for i, j in VOIGT], axis=1)
    tangent = np.stack(
        [np.stack([ddsdde[:, i, j, k, l] for k, l in VOIGT], 1) for i, j in VOIGT], 1
    )
    return stress, tangent, W


def volumetric(J, U, JdU, J2d2U):
    """Kirchhoff volumetric stress and tangent from U(J): tau = J U' I,
    J c = (J U' + J^2 U'') I (x) I - 2 J U' II.
    """
    m = J.shape[0]
    one = eye(m)
    tau = JdU[:, None, None] * one
    ptil = JdU + J2d2U
    Jc = ptil[:, None, None, None, None] * dyad(one, one)
    Jc = Jc - 2.0 * JdU[:, None, None, None, None] * symdyad(one, one)
    return tau, Jc


def log_squared(J, k0):
    lnJ = np.log(J)
    return 0.5 * k0 * lnJ**2, k0 * lnJ, k0 * (1.0 - lnJ)


def isochoric(F, J, psi):
    """Decoupled spatial form (Abaqus theory manual / Holzapfel 6.6): tau_iso, J c_iso, Psi."""
    m = F.shape[0]
    one = eye(m)
    bb = J[:, None, None] ** (-2.0 / 3.0) * np.einsum("miK,mjK->mij", F, F)
    bb2 = np.einsum("mik,mkj->mij", bb, bb)
    I1b = np.einsum("mii->m", bb)
    I2b = 0.5 * (I1b**2 - np.einsum("mii->m", bb2))
    W, p1, p2, p11, p12, p22 = psi(I1b, I2b)
    p1, p2, p11, p12, p22 = (
        np.broadcast_to(np.asarray(q, dtype=DT), (m,)) for q in (p1, p2, p11, p12, p22)
    )
    s = lambda q: q[:, None, None]
    S4 = lambda q: q[:, None, None, None, None]
    taub = 2.0 * s(p1 + I1b * p2) * bb - 2.0 * s(p2) * bb2
    trt = np.einsum("mii->m", taub)
    tiso = taub - s(trt / 3.0) * one
    Ab = s(I1b) * bb - bb2
    cbar = S4(p11) * dyad(bb, bb) + S4(p12) * (dyad(bb, Ab) + dyad(Ab, bb)) + S4(p22) * dyad(Ab, Ab)
    cbar = 4.0 * (cbar + S4(p2) * (dyad(bb, bb) - symdyad(bb, bb)))
    P = symdyad(one, one) - dyad(one, one) / 3.0
    Jc = dev4(cbar) + (2.0 / 3.0) * S4(trt) * P - (2.0 / 3.0) * (dyad(one, tiso) + dyad(tiso, one))
    return tiso, Jc, W


def decoupled(F, k0, psi):
    J = np.linalg.det(F)
    tiso, Jciso, Wiso = isochoric(F, J, psi)
    U, JdU, J2d2U = log_squared(J, k0)
    tvol, Jcvol = volumetric(J, U, JdU, J2d2U)
    return umat_return(tiso + tvol, Jciso + Jcvol, J, Wiso + U)


# ---------------------------------------------------------------- the UMATs (PROPS as listed)


def umat_neo_hookean(F, props, frame=None):
    mu, lam = props
    m = F.shape[0]
    one = eye(m)
    J = np.linalg.det(F)
    lnJ = np.log(J)
    b = np.einsum("miK,mjK->mij", F, F)
    I1 = np.einsum("mii->m", b)
    W = 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2
    tau = mu * (b - one) + lam * lnJ[:, None, None] * one
    Jc = lam * dyad(one, one) + 2.0 * (mu - lam * lnJ)[:, None, None, None, None] * symdyad(
        one, one
    )
    return umat_return(tau, Jc, J, W)


def umat_mooney_rivlin(F, props, frame=None):
    c10, c01, d1 = props
    k0 = 2.0 / d1
    psi = lambda I1b, I2b: (c10 * (I1b - 3.0) + c01 * (I2b - 3.0), c10, c01, 0.0, 0.0, 0.0)
    return decoupled(F, k0, psi)


def umat_yeoh(F, props, frame=None):
    c10, c20, c30, k0 = props

    def psi(I1b, I2b):
        x = I1b - 3.0
        W = c10 * x + c20 * x**2 + c30 * x**3
        return W, c10 + 2.0 * c20 * x + 3.0 * c30 * x**2, 0.0, 2.0 * c20 + 6.0 * c30 * x, 0.0, 0.0

    return decoupled(F, k0, psi)


AB_C = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def umat_arruda_boyce(F, props, frame=None):
    mu, N, k0 = props
    a = [mu * c * N ** (1 - i) for i, c in enumerate(AB_C, start=1)]

    def psi(I1b, I2b):
        W = sum(a[i - 1] * (I1b**i - 3.0**i) for i in range(1, 6))
        p1 = sum(i * a[i - 1] * I1b ** (i - 1) for i in range(1, 6))
        p11 = sum(i * (i - 1) * a[i - 1] * I1b ** (i - 2) for i in range(2, 6))
        return W, p1, 0.0, p11, 0.0, 0.0

    return decoupled(F, k0, psi)


def umat_gent(F, props, frame=None):
    mu, Jm, k0 = props

    def psi(I1b, I2b):
        d = 1.0 - (I1b - 3.0) / Jm
        p1 = 0.5 * mu / d
        return -0.5 * mu * Jm * np.log(d), p1, 0.0, p1 / (Jm * d), 0.0, 0.0

    return decoupled(F, k0, psi)


def umat_veronda_westmann(F, props, frame=None):
    c1, c2, k0 = props

    def psi(I1b, I2b):
        e = np.exp(c2 * (I1b - 3.0))
        W = c1 * (e - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0)
        return W, c1 * c2 * e, -0.5 * c1 * c2, c1 * c2 * c2 * e, 0.0, 0.0

    return decoupled(F, k0, psi)


def umat_demiray(F, props, frame=None):
    a, b, k0 = props

    def psi(I1b, I2b):
        e = np.exp(b * (I1b - 3.0))
        return a / (2.0 * b) * (e - 1.0), 0.5 * a * e, 0.0, 0.5 * a * b * e, 0.0, 0.0

    return decoupled(F, k0, psi)


def umat_ogden(F, props, frame=None):
    """Spectral form: principal Kirchhoff stresses beta_a = mu/alpha (lb_a^alpha - S/3)."""
    mu, alpha, k0 = props
    m = F.shape[0]
    J = np.linalg.det(F)
    b = np.einsum("miK,mjK->mij", F, F)
    x, n = np.linalg.eigh(b)
    xb = J[:, None] ** (-2.0 / 3.0) * x  # squared isochoric stretches
    L = xb ** (alpha / 2.0)
    S = L.sum(axis=1)
    mm = mu / alpha
    beta = mm * (L - S[:, None] / 3.0)
    N = np.einsum("mia,mjb->mabij", n, n)  # N[a, b] = n_a (x) n_b
    Naa = np.einsum("maaij->maij", N)
    tiso = np.einsum("ma,maij->mij", beta, Naa)
    dbeta = (
        mm
        * alpha
        * (
            L[:, :, None] * np.eye(3, dtype=DT)
            - L[:, :, None] / 3.0
            - L[:, None, :] / 3.0
            + S[:, None, None] / 9.0
        )
    )
    dbeta = dbeta - 2.0 * beta[:, :, None] * np.eye(3, dtype=DT)
    Jc = np.einsum("mab,maij,mbkl->mijkl", dbeta, Naa, Naa)
    r = alpha / 2.0 - 1.0
    for a_, b_ in ((0, 1), (1, 0), (0, 2), (2, 0), (1, 2), (2, 1)):
        xa, xb_ = xb[:, a_], xb[:, b_]
        lt = np.log(xa / xb_)
        safe = np.where(lt == 0.0, 1.0, lt)
        ratio = np.where(lt == 0.0, r, np.expm1(r * safe) / np.expm1(safe))
        gam = mm * (xa * xb_**r * ratio + S / 3.0)
        Nab, Nba = N[:, a_, b_], N[:, b_, a_]
        Jc = Jc + gam[:, None, None, None, None] * (dyad(Nab, Nab) + dyad(Nab, Nba))
    U, JdU, J2d2U = log_squared(J, k0)
    tvol, Jcvol = volumetric(J, U, JdU, J2d2U)
    W = mu / alpha**2 * (S - 3.0) + U
    return umat_return(tiso + tvol, Jc + Jcvol, J, W + 0.0 * m)


def umat_st_venant_kirchhoff(F, props, frame=None):
    mu, lam = props
    m = F.shape[0]
    one = eye(m)
    J = np.linalg.det(F)
    C = np.einsum("mKi,mKj->mij", F, F)
    E = 0.5 * (C - one)
    trE = np.einsum("mii->m", E)
    W = 0.5 * lam * trE**2 + mu * np.einsum("mij,mij->m", E, E)
    S = lam * trE[:, None, None] * one + 2.0 * mu * E
    b = np.einsum("miK,mjK->mij", F, F)
    Jc = lam * dyad(b, b) + 2.0 * mu * symdyad(b, b)
    return umat_return(push2(F, S), Jc, J, W)


def umat_costa(F, props, frame):
    """Fibre-frame UMAT: Ef = R^T E R, Q = sum B_ij Ef_ij^2, W = a/2 (exp(J^(-4/3) Q) - 1)."""
    a, k0, bff, bfs, bss, bfn, bsn, bnn = props
    B = np.array([[bff, bfs, bfn], [bfs, bss, bsn], [bfn, bsn, bnn]], dtype=DT)
    m = F.shape[0]
    one = eye(m)
    R = frame
    J = np.linalg.det(F)
    C = np.einsum("mKi,mKj->mij", F, F)
    Ci = np.linalg.inv(C)
    Ef = np.einsum("mai,mab,mbj->mij", R, 0.5 * (C - one), R)
    Q = np.einsum("ij,mij->m", B, Ef * Ef)
    H = rot2(R, B * Ef)  # dQ/dC
    d = np.eye(3, dtype=DT)
    Tf = 0.25 * (np.einsum("ab,ac,bd->abcd", B, d, d) + np.einsum("ab,ad,bc->abcd", B, d, d))
    dH = rot4(R, np.broadcast_to(Tf, (m, 3, 3, 3, 3)))
    j43 = J ** (-4.0 / 3.0)
    s = lambda q: q[:, None, None]
    S4 = lambda q: q[:, None, None, None, None]
    G = s(j43) * (H - (2.0 / 3.0) * s(Q) * Ci)
    e = np.exp(j43 * Q)
    d2 = -(2.0 / 3.0) * (dyad(H, Ci) + dyad(Ci, H)) + (4.0 / 9.0) * S4(Q) * dyad(Ci, Ci)
    d2 = S4(j43) * (d2 + (2.0 / 3.0) * S4(Q) * symdyad(Ci, Ci) + dH)
    S = a * s(e) * G
    CC = 2.0 * a * S4(e) * (dyad(G, G) + d2)
    lnJ = np.log(J)
    U = k0 * (J * lnJ - J + 1.0)
    tvol, Jcvol = volumetric(J, U, k0 * J * lnJ, k0 * J)
    W = 0.5 * a * (e - 1.0) + U
    return umat_return(push2(F, S) + tvol, push4(F, CC) + Jcvol, J, W)


UMATS = {
    "NeoHookean": (umat_neo_hookean, lambda p: (p["mu"], p["lam"])),
    "MooneyRivlin": (umat_mooney_rivlin, lambda p: (p["c1"], p["c2"], 2.0 / p["k0"])),
    "Yeoh": (umat_yeoh, lambda p: (p["c10"], p["c20"], p["c30"], p["k0"])),
    "ArrudaBoyce": (umat_arruda_boyce, lambda p: (p["mu"], p.get("N", 8.0), p["k0"])),
    "Gent": (umat_gent, lambda p: (p["mu"], p["Jm"], p["k0"])),
    "VerondaWestmann": (umat_veronda_westmann, lambda p: (p["c1"], p["c2"], p["k0"])),
    "Demiray": (umat_demiray, lambda p: (p["a"], p["b"], p["k0"])),
    "Ogden": (umat_ogden, lambda p: (p["mu"], p["alpha"], p["k0"])),
    "StVenantKirchhoff": (umat_st_venant_kirchhoff, lambda p: (p["mu"], p["lam"])),
    "Costa": (
        umat_costa,
        lambda p: tuple(p[k] for k in ("a", "k0", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")),
    ),
}


def fd_ddsdde(umat, F, props, frame, stress, eps=1e-7):
    """DDSDDE by perturbing DFGRD1 (Sun, Chaikof and Levenston 2008): forward differences of
    the Kirchhoff stress, F + eps/2 (e_i e_j + e_j e_i) F for each Voigt component (i, j).
    """
    J = np.linalg.det(F)
    tau = J[:, None] * stress
    cols = []
    for i, j in VOIGT:
        dF = np.zeros((3, 3), dtype=DT)
        dF[i, j] += 0.5 * eps
        dF[j, i] += 0.5 * eps
        Fp = F + dF
        sp_, _, _ = umat(Fp, props, frame)
        cols.append((np.linalg.det(Fp)[:, None] * sp_ - tau) / (J[:, None] * eps))
    return np.stack(cols, axis=2)


# ---------------------------------------------------------------- the driver


def unpack(stress, ddsdde):
    """STRESS and DDSDDE (Voigt) -> sigma (m, 3, 3) and the Jaumann tangent (m, 3, 3, 3, 3)."""
    m = stress.shape[0]
    sig = np.zeros((m, 3, 3), dtype=DT)
    D = np.zeros((m, 3, 3, 3, 3), dtype=DT)
    for I, (i, j) in enumerate(UNPACK):
        sig[:, i, j] = stress[:, I]
        sig[:, j, i] = stress[:, I]
        for K, (k, l) in enumerate(UNPACK):
            for p, q in {(i, j), (j, i)}:
                for r, t in {(k, l), (l, k)}:
                    D[:, p, q, r, t] = ddsdde[:, I, K]
    return sig, D


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        raw = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = raw.reshape(spec["shape"])
    return case, arrays


def compute(case, arrays):
    name = case["model"]["name"]
    params = {k: float(v) for k, v in case["model"]["parameters"].items()}
    umat, props_of = UMATS[name]
    props = tuple(DT(v) for v in props_of(params))
    X = arrays["points"].astype(DT)[arrays["cells"]]
    x = arrays["positions"].astype(DT)[arrays["cells"]]
    cells = arrays["cells"]
    m = cells.shape[0]
    DX = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    Dx = np.swapaxes(x[:, 1:] - x[:, :1], 1, 2)
    V = np.linalg.det(DX) / 6.0
    DXi = np.linalg.inv(DX)
    G = np.concatenate([-DXi.sum(axis=1, keepdims=True), DXi], axis=1)  # dN_a/dX
    F = Dx @ DXi
    J = np.linalg.det(F)
    g = G @ np.linalg.inv(F)  # dN_a/dx
    v = J * V
    frame = None
    if "frame" in arrays:
        frame = arrays["frame"].astype(DT).reshape(m, 3, 3)
    stress, ddsdde, sse = umat(F, props, frame)
    ddsdde = fd_ddsdde(umat, F, props, frame, stress)  # numerical DDSDDE
    sig, D = unpack(stress, ddsdde)
    c = D - jaumann(sig)  # Truesdell (Oldroyd) spatial tangent
    fe = -np.einsum("m,mij,maj->mai", v, sig, g)
    Km = np.einsum("maj,mijkl,mbl->maibk", g, c, g)
    Kg = np.einsum("maj,mjl,mbl->mab", g, sig, g)
    Ke = v[:, None, None, None, None] * (Km + np.einsum("mab,ik->maibk", Kg, np.eye(3, dtype=DT)))
    energy = np.sum(V * sse)
    n = arrays["points"].shape[0]
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=DT)
    np.add.at(force, dofs.ravel(), fe.reshape(-1))
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.reshape(m, 144).ravel()
    return force, (rows, cols, vals), energy, n


def write(out, force, triplets, energy, n):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fdt = "<f4" if SUFFIX == ".f32" else "<f8"
    force.astype(fdt).tofile(out / f"force{SUFFIX}")
    rows, cols, vals = triplets
    if LAYOUT == "coo":
        rows.astype("<i8").tofile(out / "stiffness_rows.i64")
        cols.astype("<i8").tofile(out / "stiffness_cols.i64")
        vals.astype(fdt).tofile(out / f"stiffness_values{SUFFIX}")
    elif LAYOUT == "csr":
        K = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n))
        K.sum_duplicates()
        K.indptr.astype("<i8").tofile(out / "stiffness_indptr.i64")
        K.indices.astype("<i8").tofile(out / "stiffness_indices.i64")
        K.data.astype(fdt).tofile(out / f"stiffness_values{SUFFIX}")
    else:
        K = np.zeros((3 * n, 3 * n), dtype=DT)
        np.add.at(K, (rows, cols), vals)
        K.astype(fdt).tofile(out / f"stiffness{SUFFIX}")
    np.array([energy]).astype(fdt).tofile(out / f"energy{SUFFIX}")


def main(argv):
    case, arrays = read_case(argv[1])
    force, triplets, energy, n = compute(case, arrays)
    write(argv[2], force, triplets, energy, n)


if __name__ == "__main__":
    main(sys.argv)
