#!/usr/bin/env python3
# MISTAKE: element stiffness matrices stored in a float32 buffer (to halve the memory) before
# assembly; force and energy float64, .f64 outputs.
"""Total-Lagrangian P1-tetrahedron engine after Holzapfel, Nonlinear Solid Mechanics, ch. 6.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one mjed-verify kit case).

Per cell, vectorised over the cells: the reference gradients G_a = dN_a/dX, F, J, C = F^T F and
C^-1; the second Piola-Kirchhoff stress S and the material elasticity tensor CC = 4 d2W/dCdC,
in Holzapfel's decoupled form (S = S_vol + S_iso, CC = CC_vol + CC_iso, eqs. 6.89-6.91 and
6.165-6.168) for the laws written in isochoric invariants and directly (S = 2 dW/dC) for the
others; then the first Piola stress P = F S and the first elasticity tensor
A_iJkL = delta_ik S_JL + F_iI F_kK CC_IJKL; f_a = -V P G_a, K_ab,ik = V G_aJ A_iJkL G_bL,
energy sum V W.
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

DTYPE = np.float64
SUFFIX = ".f64"
LAYOUT = "csr"  # how the stiffness is written: "coo", "csr" or "dense"
I3 = np.eye(3, dtype=DTYPE)
II = 0.5 * (np.einsum("ik,jl->ijkl", I3, I3) + np.einsum("il,jk->ijkl", I3, I3))


# ----------------------------------------------------------------------------- tensor algebra
def col(a):
    """A per-cell scalar (m,) broadcast against (m, 3, 3)."""
    return a[:, None, None]


def col4(a):
    """A per-cell scalar (m,) broadcast against (m, 3, 3, 3, 3)."""
    return a[:, None, None, None, None]


def outer(A, B):
    """(A (x) B)_IJKL = A_IJ B_KL."""
    return np.einsum("mij,mkl->mijkl", A, B)


def odot(A, B):
    """(A (.) B)_IJKL = (A_IK B_JL + A_IL B_JK) / 2 (Holzapfel's symmetric product)."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def dot2(A, B):
    """A : B, per cell."""
    return np.einsum("mij,mij->m", A, B)


# ----------------------------------------------------------------------------- input
def read_case(folder):
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        raw = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = raw.reshape(spec["shape"])
    return case, arrays


def reference_gradients(X, cells):
    """G (m, 4, 3): G_a = dN_a/dX; V (m,): rest volumes."""
    Xe = X[cells]
    M = np.stack([Xe[:, 1] - Xe[:, 0], Xe[:, 2] - Xe[:, 0], Xe[:, 3] - Xe[:, 0]], axis=2)
    V = np.linalg.det(M) / 6.0
    Minv = np.linalg.inv(M)  # its rows are G_1, G_2, G_3
    G = np.empty((len(cells), 4, 3), dtype=DTYPE)
    G[:, 1:] = Minv
    G[:, 0] = -Minv.sum(axis=1)
    return G, V


# ----------------------------------------------------------------------------- volumetric part
def volumetric(name, p, J):
    """U(J), p = dU/dJ and dp/dJ."""
    lnJ = np.log(J)
    if name == "NeoHookean":
        mu, lam = p["mu"], p["lam"]
        return -mu * lnJ + 0.5 * lam * lnJ**2, (lam * lnJ - mu) / J, (mu + lam - lam * lnJ) / J**2
    if name == "Costa":
        k0 = p["k0"]
        return k0 * (J * lnJ - J + 1.0), k0 * lnJ, k0 / J
    k0 = p["k0"]
    return 0.5 * k0 * lnJ**2, k0 * lnJ / J, k0 * (1.0 - lnJ) / J**2


def volumetric_stress(J, Ci, U, dU, d2U):
    """S_vol = J p C^-1, CC_vol = J p~ C^-1 (x) C^-1 - 2 J p C^-1 (.) C^-1 (eqs. 6.89, 6.166)."""
    p = dU
    pt = p + J * d2U  # p~ = p + J dp/dJ
    S_vol = col(J * p) * Ci
    CC_vol = col4(J * pt) * outer(Ci, Ci) - col4(2.0 * J * p) * odot(Ci, Ci)
    return S_vol, CC_vol


# ----------------------------------------------------------------------------- isochoric laws
def invariant_law(name, p, I1b, I2b):
    """Psi(I1b, I2b) and its derivatives psi1, psi2, psi11, psi12, psi22."""
    one, zero = np.ones_like(I1b), np.zeros_like(I1b)
    if name == "MooneyRivlin":
        c1, c2 = p["c1"], p["c2"]
        return c1 * (I1b - 3.0) + c2 * (I2b - 3.0), c1 * one, c2 * one, zero, zero, zero
    if name == "Yeoh":
        c10, c20, c30 = p["c10"], p["c20"], p["c30"]
        x = I1b - 3.0
        psi = c10 * x + c20 * x**2 + c30 * x**3
        psi1 = c10 + 2.0 * c20 * x + 3.0 * c30 * x**2
        psi11 = 2.0 * c20 + 6.0 * c30 * x
        return psi, psi1, zero, psi11, zero, zero
    if name == "ArrudaBoyce":
        mu, N = p["mu"], p.get("N", 8.0)
        coeffs = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)
        psi, psi1, psi11 = zero.copy(), zero.copy(), zero.copy()
        for i, c in enumerate(coeffs, start=1):
            a = mu * c * N ** (1 - i)
            psi = psi + a * (I1b**i - 3.0**i)
            psi1 = psi1 + i * a * I1b ** (i - 1)
            psi11 = psi11 + i * (i - 1) * a * I1b ** max(i - 2, 0)
        return psi, psi1, zero, psi11, zero, zero
    if name == "Gent":
        mu, Jm = p["mu"], p["Jm"]
        pref = 0.5 * mu * Jm
        d = 1.0 - (I1b - 3.0) / Jm
        return -pref * np.log(d), pref / (Jm * d), zero, pref / (Jm * d) ** 2, zero, zero
    if name == "VerondaWestmann":
        c1, c2 = p["c1"], p["c2"]
        e = np.exp(c2 * (I1b - 3.0))
        psi = c1 * (e - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0)
        psi1 = c1 * c2 * e
        psi11 = c1 * c2 * c2 * e
        return psi, psi1, -0.5 * c1 * c2 * one, psi11, zero, zero
    if name == "Demiray":
        a, b = p["a"], p["b"]
        pref = a / (2.0 * b)
        e = np.exp(b * (I1b - 3.0))
        return pref * (e - 1.0), pref * b * e, zero, pref * b * b * e, zero, zero
    raise SystemExit(f"unknown isochoric law {name}")


def fictitious_invariants(name, p, Cb):
    """Psi, the fictitious stress S_bar = 2 dPsi/dC_bar and elasticity 4 d2Psi/dC_bar dC_bar."""
    I1b = np.trace(Cb, axis1=1, axis2=2)
    I2b = 0.5 * (I1b**2 - np.einsum("mij,mji->m", Cb, Cb))
    psi, psi1, psi2, psi11, psi12, psi22 = invariant_law(name, p, I1b, I2b)
    Id = np.broadcast_to(I3, Cb.shape)
    Sbar = 2.0 * col(psi1 + I1b * psi2) * Id - 2.0 * col(psi2) * Cb
    # Holzapfel (6.193) with the isochoric invariants of C_bar
    d1 = psi11 + 2.0 * I1b * psi12 + psi2 + I1b**2 * psi22
    d2 = -(psi12 + I1b * psi22)
    CCbar = 4.0 * (
        col4(d1) * outer(Id, Id)
        + col4(d2) * (outer(Id, Cb) + outer(Cb, Id))
        + col4(psi22) * outer(Cb, Cb)
        - col4(psi2) * np.broadcast_to(II, Cb.shape[:1] + II.shape)
    )
    return psi, Sbar, CCbar


def power_divided_difference(u, c, r):
    """theta_ab = (c u_b^r - c u_a^r) / (u_b - u_a), its limit c r u^(r-1) where u_a = u_b,
    without cancellation (expm1/log1p).
    """
    ua, ub = u[:, :, None], u[:, None, :]
    x = (ub - ua) / ua
    safe = np.where(x == 0.0, 1.0, x)
    ratio = np.where(x == 0.0, r, np.expm1(r * np.log1p(safe)) / safe)
    return c * ua ** (r - 1.0) * ratio


def fictitious_ogden(p, Cb):
    """Ogden through the principal stretches of C_bar (Holzapfel 6.5, eq. 6.196)."""
    mu, alpha = p["mu"], p["alpha"]
    e, N = np.linalg.eigh(Cb)  # eigenvalues lam_a^2 of C_bar, principal directions (columns)
    lam = np.sqrt(e)
    psi = mu / alpha**2 * (np.sum(lam**alpha, axis=1) - 3.0)
    c = mu / alpha
    k = alpha - 2.0  # S_bar_a = (1/lam_a) dPsi/dlam_a = c lam_a^k
    Sa = c * lam**k
    diag = c * k * lam ** (k - 2.0)  # (1/lam_a) dS_bar_a/dlam_a
    theta = power_divided_difference(e, c, 0.5 * k)  # (S_b - S_a)/(lam_b^2 - lam_a^2)
    NN = np.einsum("mia,mja->maij", N, N)  # N_a (x) N_a
    Sbar = np.einsum("ma,maij->mij", Sa, NN)
    CCbar = np.einsum("ma,maij,makl->mijkl", diag, NN, NN)
    off = 1.0 - np.eye(3, dtype=DTYPE)
    Nab = np.einsum("mia,mjb->mabij", N, N)  # N_a (x) N_b
    CCbar = CCbar + np.einsum(
        "mab,mabij,mabkl->mijkl", theta * off, Nab, Nab + np.swapaxes(Nab, 1, 2)
    )
    return psi, Sbar, CCbar


def DEV(A, C, Ci):
    """Holzapfel's deviatoric operator in the reference configuration, (.) - 1/3 ((.):C) C^-1."""
    return A - col(dot2(A, C) / 3.0) * Ci


def decoupled(name, p, C, Ci, J):
    """W, S = S_vol + S_iso and CC = CC_vol + CC_iso (Holzapfel 6.4 and 6.6)."""
    m = len(J)
    Jm23 = J ** (-2.0 / 3.0)
    Cb = col(Jm23) * C
    if name == "Ogden":
        psi, Sbar, CCbar = fictitious_ogden(p, Cb)
    else:
        psi, Sbar, CCbar = fictitious_invariants(name, p, Cb)
    U, dU, d2U = volumetric(name, p, J)
    S_vol, CC_vol = volumetric_stress(J, Ci, U, dU, d2U)
    S_iso = col(Jm23) * DEV(Sbar, C, Ci)
    # projection tensor P = II - 1/3 C^-1 (x) C and P~ = C^-1 (.) C^-1 - 1/3 C^-1 (x) C^-1
    Id4 = np.broadcast_to(II, (m,) + II.shape)
    Proj = Id4 - outer(Ci, C) / 3.0
    Ptilde = odot(Ci, Ci) - outer(Ci, Ci) / 3.0
    CCt = col4(Jm23**2) * CCbar  # J^(-4/3) CC_bar
    trS = Jm23 * dot2(Sbar, C)  # Tr(J^(-2/3) S_bar) = J^(-2/3) S_bar : C
    CC_iso = np.einsum("mijab,mabcd,mklcd->mijkl", Proj, CCt, Proj)
    CC_iso = CC_iso + 2.0 / 3.0 * col4(trS) * Ptilde
    CC_iso = CC_iso - 2.0 / 3.0 * (outer(Ci, S_iso) + outer(S_iso, Ci))
    return psi + U, S_vol + S_iso, CC_vol + CC_iso


# ----------------------------------------------------------------------------- direct laws
def neo_hookean(p, C, Ci, J):
    """W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2: S = mu I + J U'(J) C^-1."""
    I1 = np.trace(C, axis1=1, axis2=2)
    U, dU, d2U = volumetric("NeoHookean", p, J)
    S_vol, CC_vol = volumetric_stress(J, Ci, U, dU, d2U)
    W = 0.5 * p["mu"] * (I1 - 3.0) + U
    return W, p["mu"] * I3 + S_vol, CC_vol


def st_venant_kirchhoff(p, C, Ci, J):
    """W = lam/2 (tr E)^2 + mu tr(E^2): S = lam tr(E) I + 2 mu E, CC = lam I (x) I + 2 mu II."""
    mu, lam = p["mu"], p["lam"]
    E = 0.5 * (C - I3)
    trE = np.trace(E, axis1=1, axis2=2)
    W = 0.5 * lam * trE**2 + mu * np.einsum("mij,mji->m", E, E)
    S = lam * col(trE) * I3 + 2.0 * mu * E
    CC = lam * np.einsum("ij,kl->ijkl", I3, I3) + 2.0 * mu * II
    return W, S, np.broadcast_to(CC, (len(J),) + CC.shape)


def costa_B(p):
    return np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ],
        dtype=DTYPE,
    )


def costa(p, C, Ci, J, R):
    """W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum B_ij Ef_ij^2, Ef = R^T E R.

    Q is written in E, not in an isochoric strain: S = 2 dW/dC directly.
    """
    a = p["a"]
    B = costa_B(p)
    E = 0.5 * (C - I3)
    Ef = np.einsum("mai,mab,mbj->mij", R, E, R)
    Q = np.einsum("ij,mij->m", B, Ef**2)
    T = np.einsum("mia,mab,mjb->mij", R, B * Ef, R)  # dQ/dC = R (B o Ef) R^T
    g = J ** (-4.0 / 3.0)
    kappa = -2.0 / 3.0  # d J^(-4/3) / dC = kappa J^(-4/3) C^-1
    Qh = g * Q
    eQ = np.exp(Qh)
    H = col(g) * (T + col(kappa * Q) * Ci)  # dQh/dC
    # dT_IJKL = 1/4 sum_ab B_ab R_Ia R_Jb (R_Ka R_Lb + R_La R_Kb)
    dT = 0.25 * (
        np.einsum("ab,mia,mjb,mka,mlb->mijkl", B, R, R, R, R)
        + np.einsum("ab,mia,mjb,mla,mkb->mijkl", B, R, R, R, R)
    )
    d2Qh = col4(g) * (
        dT
        + kappa * (outer(T, Ci) + outer(Ci, T))
        + col4(kappa**2 * Q) * outer(Ci, Ci)
        - col4(kappa * Q) * odot(Ci, Ci)
    )
    U, dU, d2U = volumetric("Costa", p, J)
    S_vol, CC_vol = volumetric_stress(J, Ci, U, dU, d2U)
    W = 0.5 * a * (eQ - 1.0) + U
    S = a * col(eQ) * H + S_vol
    CC = 2.0 * a * col4(eQ) * (outer(H, H) + d2Qh) + CC_vol
    return W, S, CC


ISOCHORIC = ("MooneyRivlin", "Yeoh", "ArrudaBoyce", "Gent", "VerondaWestmann", "Demiray", "Ogden")


def material(name, p, C, J, frame):
    Ci = np.linalg.inv(C)
    if name in ISOCHORIC:
        return decoupled(name, p, C, Ci, J)
    if name == "NeoHookean":
        return neo_hookean(p, C, Ci, J)
    if name == "StVenantKirchhoff":
        return st_venant_kirchhoff(p, C, Ci, J)
    if name == "Costa":
        return costa(p, C, Ci, J, frame)
    raise SystemExit(f"unsupported material {name}")


# ----------------------------------------------------------------------------- element, output
def cell_frames(arrays, m):
    if "frame" not in arrays:
        return None
    R = arrays["frame"].astype(DTYPE)
    return np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R


def compute(case, arrays):
    name = case["model"]["name"]
    p = {k: float(v) for k, v in case["model"]["parameters"].items()}
    X = arrays["points"].astype(DTYPE)
    x = arrays["positions"].astype(DTYPE)
    cells = arrays["cells"].astype(np.int64)
    m = len(cells)
    G, V = reference_gradients(X, cells)
    F = np.einsum("mak,maI->mkI", x[cells], G)  # F_kI = sum_a x_ak G_aI
    J = np.linalg.det(F)
    C = np.einsum("mkI,mkJ->mIJ", F, F)
    W, S, CC = material(name, p, C, J, cell_frames(arrays, m))
    P = np.einsum("miK,mKJ->miJ", F, S)  # first Piola stress
    A = np.einsum("ik,mJL->miJkL", I3, S) + np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F)
    fe = -col(V) * np.einsum("miJ,maJ->mai", P, G)  # f_a = -V P G_a
    Ke = np.einsum("maJ,miJkL,mbL->maibk", G, A, G) * col4(V)
    Ke_buffer = np.empty((m, 12, 12), dtype=np.float32)  # element matrices in float32 (memory)
    Ke_buffer[...] = Ke.reshape(m, 12, 12)
    Ke = Ke_buffer
    energy = np.sum(V * W)
    return fe, Ke, energy


def write(out, n, cells, fe, Ke, energy):
    out.mkdir(parents=True, exist_ok=True)
    m = len(cells)
    force = np.zeros((n, 3), dtype=DTYPE)
    np.add.at(force, cells, fe)
    force.astype(DTYPE).tofile(out / ("force" + SUFFIX))
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.reshape(-1).astype(DTYPE)
    if LAYOUT == "coo":
        rows.astype("<i8").tofile(out / "stiffness_rows.i64")
        cols.astype("<i8").tofile(out / "stiffness_cols.i64")
        vals.tofile(out / ("stiffness_values" + SUFFIX))
    elif LAYOUT == "csr":
        K = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n))
        K.sum_duplicates()
        K.indptr.astype("<i8").tofile(out / "stiffness_indptr.i64")
        K.indices.astype("<i8").tofile(out / "stiffness_indices.i64")
        K.data.astype(DTYPE).tofile(out / ("stiffness_values" + SUFFIX))
    else:
        K = np.zeros((3 * n, 3 * n), dtype=DTYPE)
        np.add.at(K, (rows, cols), vals)
        K.tofile(out / ("stiffness" + SUFFIX))
    np.array([energy], dtype=DTYPE).tofile(out / ("energy" + SUFFIX))


def main(argv):
    if len(argv) != 3:
        raise SystemExit("usage: ENGINE INPUT_DIR OUTPUT_DIR")
    case, arrays = read_case(Path(argv[1]))
    fe, Ke, energy = compute(case, arrays)
    write(Path(argv[2]), case["n_nodes"], arrays["cells"].astype(np.int64), fe, Ke, energy)


if __name__ == "__main__":
    main(sys.argv)
