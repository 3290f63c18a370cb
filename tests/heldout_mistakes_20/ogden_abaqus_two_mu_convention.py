#!/usr/bin/env python3
# MISTAKE: Ogden routine written in Abaqus' convention U = 2 mu/alpha^2 (sum lb^alpha - 3) and
# given the kit's mu, whose law is mu/alpha^2 (sum lb^alpha - 3) (the kit's mu is already Abaqus' 2
# mu_1): isochoric energy and its derivatives doubled (initial shear modulus 2 mu); energy, force
# and stiffness wrong in both states.
"""P1 tetrahedral hyperelastic engine, user-material style (Abaqus UHYPER / UANISOHYPER_STRAIN).

Two layers, as in a commercial code's user material:

- a USER ROUTINE per material returns, per cell, the energy density U and its derivatives packed
  as arrays: invariant routines (UHYPER manner) UI1 = (dU/dI1b, dU/dI2b, dU/dJ) and
  UI2 = (d2U/dI1b2, d2U/dI2b2, d2U/dJ2, d2U/dI1b dI2b, d2U/dI1b dJ, d2U/dI2b dJ);
  the strain routine (UANISOHYPER_STRAIN manner, Costa) DUDE (6) and D2UDE2 (21, the packed upper
  triangle row by row) with respect to the Green-Lagrange strain in the cell's fibre frame, Voigt
  order 11, 22, 33, 23, 13, 12 with engineering shears (eps = E11, E22, E33, 2 E23, 2 E13, 2 E12);
  the principal-stretch routine (Ogden) dU/dlb_i, d2U/dlb_i dlb_j of the deviatoric stretches
  lb_i = J^(-1/3) lambda_i, dU/dJ and d2U/dJ2;
- a GENERIC DRIVER per routine type turns them into the second Piola-Kirchhoff stress
  S = 2 dU/dC and the material tangent C_mat = 4 d2U/dC2 (6x6, Voigt order 11, 22, 33, 23, 13, 12);
  the element builds the material B matrix (6 x 12, engineering shear rows) from F and the rest
  shape-function gradients, f_e = -V0 B^T S, K_e = V0 B^T C_mat B + V0 (G_a . S . G_b) I.

usage: python ENGINE INPUT_DIR OUTPUT_DIR
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "dense"
WRITE_ENERGY = True

# Voigt order of the driver and of the strain routine: 11, 22, 33, 23, 13, 12
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
# packed upper triangle of a symmetric 6x6, row by row: (0,0), (0,1), ..., (0,5), (1,1), ...
TRIU = [(k, l) for k in range(6) for l in range(k, 6)]


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


# ------------------------------------------------------------------ tensor helpers


def eye(m):
    return np.broadcast_to(np.eye(3, dtype=REAL), (m, 3, 3)).copy()


def outer(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def odot(A, B):
    # (A (.) B)_ijkl = 1/2 (A_ik B_jl + A_il B_jk)
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def sym_outer(A, B):
    return outer(A, B) + outer(B, A)


def trace(A):
    return np.einsum("mii->m", A)


def sc(x):
    return x[:, None, None]


def sc4(x):
    return x[:, None, None, None, None]


def to_voigt6(A):
    return np.stack([A[:, i, j] for i, j in VOIGT], axis=1)


def from_voigt6(v):
    A = np.empty((v.shape[0], 3, 3), dtype=REAL)
    for k, (i, j) in enumerate(VOIGT):
        A[:, i, j] = v[:, k]
        A[:, j, i] = v[:, k]
    return A


def to_voigt66(T):
    D = np.empty((T.shape[0], 6, 6), dtype=REAL)
    for a, (i, j) in enumerate(VOIGT):
        for b, (k, l) in enumerate(VOIGT):
            D[:, a, b] = T[:, i, j, k, l]
    return D


def from_voigt66(D):
    T = np.empty((D.shape[0], 3, 3, 3, 3), dtype=REAL)
    for a, (i, j) in enumerate(VOIGT):
        for b, (k, l) in enumerate(VOIGT):
            for p, q in {(i, j), (j, i)}:
                for r, s in {(k, l), (l, k)}:
                    T[:, p, q, r, s] = D[:, a, b]
    return T


def unpack_triu(packed):
    D = np.empty((packed.shape[0], 6, 6), dtype=REAL)
    for n, (k, l) in enumerate(TRIU):
        D[:, k, l] = packed[:, n]
        D[:, l, k] = packed[:, n]
    return D


# ------------------------------------------------------------------ user routines: invariants


def log_volumetric(k0, J):
    # U_vol = k0/2 (ln J)^2 and its first two J-derivatives
    lnJ = np.log(J)
    return 0.5 * k0 * lnJ**2, k0 * lnJ / J, k0 * (1.0 - lnJ) / J**2


def pack(U1, U2, UJ, U11, U22, UJJ, U12, U1J, U2J):
    UI1 = np.stack([U1, U2, UJ], axis=1)
    UI2 = np.stack([U11, U22, UJJ, U12, U1J, U2J], axis=1)
    return UI1, UI2


def uhyper_decoupled(Uiso, U1, U2, U11, k0, J):
    z = np.zeros_like(J)
    Uv, UJ, UJJ = log_volumetric(k0, J)
    return (Uiso + Uv,) + pack(U1 + z, U2 + z, UJ, U11 + z, z, UJJ, z, z, z)


def uhyper_mooney_rivlin(prm, I1b, I2b, J):
    c1, c2 = prm["c1"], prm["c2"]
    U = c1 * (I1b - 3.0) + c2 * (I2b - 3.0)
    return uhyper_decoupled(U, c1, c2, 0.0, prm["k0"], J)


def uhyper_veronda_westmann(prm, I1b, I2b, J):
    c1, c2 = prm["c1"], prm["c2"]
    e = np.exp(c2 * (I1b - 3.0))
    U = c1 * (e - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0)
    return uhyper_decoupled(U, c1 * c2 * e, -0.5 * c1 * c2, c1 * c2**2 * e, prm["k0"], J)


AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def uhyper_arruda_boyce(prm, I1b, I2b, J):
    mu, N = prm["mu"], prm["N"]
    U = np.zeros_like(I1b)
    U1 = np.zeros_like(I1b)
    U11 = np.zeros_like(I1b)
    for i, c in enumerate(AB_C, start=1):
        w = mu * c * N ** (1 - i)
        U = U + w * (I1b**i - 3.0**i)
        U1 = U1 + w * i * I1b ** (i - 1)
        if i >= 2:
            U11 = U11 + w * i * (i - 1) * I1b ** (i - 2)
    return uhyper_decoupled(U, U1, 0.0, U11, prm["k0"], J)


def uhyper_yeoh(prm, I1b, I2b, J):
    c10, c20, c30 = prm["c10"], prm["c20"], prm["c30"]
    x = I1b - 3.0
    U = c10 * x + c20 * x**2 + c30 * x**3
    U1 = c10 + 2.0 * c20 * x + 3.0 * c30 * x**2
    U11 = 2.0 * c20 + 6.0 * c30 * x
    return uhyper_decoupled(U, U1, 0.0, U11, prm["k0"], J)


def uhyper_gent(prm, I1b, I2b, J):
    mu, Jm = prm["mu"], prm["Jm"]
    r = 1.0 - (I1b - 3.0) / Jm
    U = -0.5 * mu * Jm * np.log(r)
    return uhyper_decoupled(U, 0.5 * mu / r, 0.0, 0.5 * mu / (Jm * r**2), prm["k0"], J)


def uhyper_demiray(prm, I1b, I2b, J):
    a, b = prm["a"], prm["b"]
    e = np.exp(b * (I1b - 3.0))
    U = 0.5 * a / b * (e - 1.0)
    return uhyper_decoupled(U, 0.5 * a * e, 0.0, 0.5 * a * b * e, prm["k0"], J)


def uhyper_neo_hookean(prm, I1b, I2b, J):
    # W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 with I1 = J^(2/3) I1b: a coupled U(I1b, J)
    mu, lam = prm["mu"], prm["lam"]
    lnJ = np.log(J)
    j23 = J ** (2.0 / 3.0)
    z = np.zeros_like(J)
    U = 0.5 * mu * (j23 * I1b - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2
    U1 = 0.5 * mu * j23
    UJ = mu / 3.0 * J ** (-1.0 / 3.0) * I1b - mu / J + lam * lnJ / J
    UJJ = -mu / 9.0 * J ** (-4.0 / 3.0) * I1b + mu / J**2 + lam * (1.0 - lnJ) / J**2
    U1J = mu / 3.0 * J ** (-1.0 / 3.0)
    return (U,) + pack(U1, z, UJ, z, z, UJJ, z, U1J, z)


def uhyper_st_venant_kirchhoff(prm, I1b, I2b, J):
    # W = lam/8 (I1 - 3)^2 + mu/4 (I1^2 - 2 I1 + 3) - mu/2 I2, I1 = J^(2/3) I1b, I2 = J^(4/3) I2b
    mu, lam = prm["mu"], prm["lam"]
    z = np.zeros_like(J)
    a, a1, a2 = J ** (2.0 / 3.0), 2.0 / 3.0 * J ** (-1.0 / 3.0), -2.0 / 9.0 * J ** (-4.0 / 3.0)
    b, b1, b2 = J ** (4.0 / 3.0), 4.0 / 3.0 * J ** (1.0 / 3.0), 4.0 / 9.0 * J ** (-2.0 / 3.0)
    I1, I2 = a * I1b, b * I2b
    U = 0.125 * lam * (I1 - 3.0) ** 2 + 0.25 * mu * (I1**2 - 2.0 * I1 + 3.0) - 0.5 * mu * I2
    W1 = 0.25 * lam * (I1 - 3.0) + 0.5 * mu * (I1 - 1.0)
    W2 = -0.5 * mu + z
    W11 = 0.25 * lam + 0.5 * mu
    U1, U2 = W1 * a, W2 * b
    UJ = W1 * I1b * a1 + W2 * I2b * b1
    U11 = W11 * a**2
    U1J = W11 * I1b * a1 * a + W1 * a1
    U2J = W2 * b1
    UJJ = W11 * (I1b * a1) ** 2 + W1 * I1b * a2 + W2 * I2b * b2
    return (U,) + pack(U1, U2, UJ, U11, z, UJJ, z, U1J, U2J)


UHYPER = {
    "MooneyRivlin": uhyper_mooney_rivlin,
    "VerondaWestmann": uhyper_veronda_westmann,
    "ArrudaBoyce": uhyper_arruda_boyce,
    "Yeoh": uhyper_yeoh,
    "Gent": uhyper_gent,
    "Demiray": uhyper_demiray,
    "NeoHookean": uhyper_neo_hookean,
    "StVenantKirchhoff": uhyper_st_venant_kirchhoff,
}


# ------------------------------------------------------------------ driver: invariants


def invariant_driver(routine, prm, C, J):
    m = C.shape[0]
    Id = eye(m)
    Ci = np.linalg.inv(C)
    I1 = trace(C)
    I2 = 0.5 * (I1**2 - trace(C @ C))
    j23, j43 = J ** (-2.0 / 3.0), J ** (-4.0 / 3.0)
    I1b, I2b = j23 * I1, j43 * I2
    U, UI1, UI2 = routine(prm, I1b, I2b, J)
    U1, U2, UJ = UI1[:, 0], UI1[:, 1], UI1[:, 2]
    U11, U22, UJJ, U12, U1J, U2J = (UI2[:, k] for k in range(6))
    # first derivatives of the invariants with respect to C
    d1 = sc(j23) * (Id - sc(I1 / 3.0) * Ci)
    A = sc(I1) * Id - C
    d2 = sc(j43) * A - sc(2.0 / 3.0 * I2b) * Ci
    dJ = sc(0.5 * J) * Ci
    S = 2.0 * (sc(U1) * d1 + sc(U2) * d2 + sc(UJ) * dJ)
    # second derivatives of the invariants with respect to C
    CC, CoC = outer(Ci, Ci), odot(Ci, Ci)
    dd1 = -sc4(j23 / 3.0) * sym_outer(Id, Ci) + sc4(I1b) * (CC / 9.0 + CoC / 3.0)
    dd2 = (
        sc4(j43) * (outer(Id, Id) - odot(Id, Id))
        - sc4(2.0 / 3.0 * j43) * sym_outer(A, Ci)
        + sc4(I2b) * (4.0 / 9.0 * CC + 2.0 / 3.0 * CoC)
    )
    ddJ = sc4(0.25 * J) * CC - sc4(0.5 * J) * CoC
    T = (
        sc4(U11) * outer(d1, d1)
        + sc4(U22) * outer(d2, d2)
        + sc4(UJJ) * outer(dJ, dJ)
        + sc4(U12) * sym_outer(d1, d2)
        + sc4(U1J) * sym_outer(d1, dJ)
        + sc4(U2J) * sym_outer(d2, dJ)
        + sc4(U1) * dd1
        + sc4(U2) * dd2
        + sc4(UJ) * ddJ
    )
    return U, S, to_voigt66(4.0 * T)


# ------------------------------------------------------------------ user routine: strain (Costa)

COSTA_B = ("b_ff", "b_fs", "b_fn", "b_fs", "b_ss", "b_sn", "b_fn", "b_sn", "b_nn")


def uanisohyper_strain_costa(prm, Ef):
    """U(Ef), DUDE (6) and D2UDE2 (21, packed upper triangle row by row) in the fibre frame."""
    m = Ef.shape[0]
    Bm = np.array([prm[n] for n in COSTA_B], dtype=REAL).reshape(3, 3)
    a, k0 = prm["a"], prm["k0"]
    Id = eye(m)
    Cf = Id + 2.0 * Ef
    J = np.sqrt(np.linalg.det(Cf))
    Ci = np.linalg.inv(Cf)
    lnJ = np.log(J)
    Q = np.einsum("ij,mij->m", Bm, Ef**2)
    j43 = J ** (-4.0 / 3.0)
    q = j43 * Q
    eq = np.exp(q)
    U = 0.5 * a * np.expm1(q) + k0 * (J * lnJ - J + 1.0)
    dQ = 2.0 * Bm[None] * Ef
    dq = sc(j43) * (dQ - sc(4.0 / 3.0 * Q) * Ci)
    dJ = sc(J) * Ci
    dU = sc(0.5 * a * eq) * dq + sc(k0 * lnJ) * dJ
    d2Q = np.zeros((m, 3, 3, 3, 3), dtype=REAL)
    for i in range(3):
        for j in range(3):
            d2Q[:, i, j, i, j] += Bm[i, j]
            d2Q[:, i, j, j, i] += Bm[i, j]
    CC, CoC = outer(Ci, Ci), odot(Ci, Ci)
    d2q = sc4(j43) * (
        d2Q - 4.0 / 3.0 * sym_outer(dQ, Ci) + sc4(16.0 / 9.0 * Q) * CC + sc4(8.0 / 3.0 * Q) * CoC
    )
    d2J = sc4(J) * (CC - 2.0 * CoC)
    d2U = sc4(0.5 * a * eq) * (outer(dq, dq) + d2q) + sc4(k0 / J) * outer(dJ, dJ)
    d2U = d2U + sc4(k0 * lnJ) * d2J
    DUDE = to_voigt6(dU)
    D = to_voigt66(d2U)
    D2UDE2 = np.stack([D[:, k, l] for k, l in TRIU], axis=1)
    return U, DUDE, D2UDE2


# ------------------------------------------------------------------ driver: strain


def strain_driver(routine, prm, E, R):
    Ef = np.einsum("mIi,mIJ,mJj->mij", R, E, R)  # Ef = R^T E R
    U, DUDE, D2UDE2 = routine(prm, Ef)
    Sf = from_voigt6(DUDE)
    Tf = from_voigt66(unpack_triu(D2UDE2))
    S = np.einsum("miI,mIJ,mjJ->mij", R, Sf, R)  # S = R Sf R^T
    T = np.einsum("miI,mjJ,mkK,mlL,mIJKL->mijkl", R, R, R, R, Tf, optimize=True)
    return U, S, to_voigt66(T)


# ---------------------------------------------------------- user routine: principal stretches


def ogden_principal(prm, lb, J):
    """One-term Ogden in the deviatoric stretches lb_i = J^(-1/3) lambda_i.

    Returns U, dU/dlb_i, d2U/dlb_i dlb_j (m, 3, 3), the divided differences
    DD_ij = (dU/dlb_j - dU/dlb_i) / (lb_j - lb_i) (m, 3, 3; d2U/dlb_i2 where they coincide),
    dU/dJ and d2U/dJ2.
    """
    mu, alpha, k0 = prm["mu"], prm["alpha"], prm["k0"]
    c = 2.0 * mu / alpha**2
    lba = lb**alpha
    Uv, UJ, UJJ = log_volumetric(k0, J)
    U = c * (lba.sum(axis=1) - 3.0) + Uv
    Ub = c * alpha * lba / lb
    Ubb = np.zeros(lb.shape + (3,), dtype=REAL)
    for i in range(3):
        Ubb[:, i, i] = c * alpha * (alpha - 1.0) * lba[:, i] / lb[:, i] ** 2
    # stable divided differences: c alpha lb_i^(alpha-2) expm1((alpha-1) d) / expm1(d)
    ln = np.log(lb)
    d = ln[:, None, :] - ln[:, :, None]  # d_ij = ln lb_j - ln lb_i
    same = d == 0.0
    ratio = np.expm1((alpha - 1.0) * d) / np.where(same, 1.0, np.expm1(d))
    ratio = np.where(same, alpha - 1.0, ratio)
    DD = c * alpha * (lba / lb**2)[:, :, None] * ratio
    return U, Ub, Ubb, DD, UJ, UJJ


# ---------------------------------------------------------------- driver: principal stretches


def principal_driver(routine, prm, C, J):
    lam2, N = np.linalg.eigh(C)
    lam = np.sqrt(lam2)
    jm13 = J ** (-1.0 / 3.0)
    lb = sc(jm13)[:, :, 0] * lam
    U, Ub, Ubb, DD, UJ, UJJ = routine(prm, lb, J)
    Id = np.eye(3, dtype=REAL)
    # deviatoric stretch chain: dlb_i/dlam_j = J^(-1/3) (delta_ij - lam_i / (3 lam_j))
    L = sc(jm13) * (Id[None] - lam[:, :, None] / (3.0 * lam[:, None, :]))
    dJ = J[:, None] / lam
    dU = np.einsum("mi,mij->mj", Ub, L) + UJ[:, None] * dJ
    # d2lb_i/dlam_j dlam_k
    inv = 1.0 / lam
    L2 = -(inv[:, None, None, :] / 3.0) * L[:, :, :, None]
    L2 = L2 + sc(jm13)[:, :, :, None] * (
        -Id[None, :, None, :] * inv[:, None, :, None] / 3.0
        + lam[:, :, None, None] * Id[None, None, :, :] * (inv**2)[:, None, :, None] / 3.0
    )
    d2J = J[:, None, None] * inv[:, :, None] * inv[:, None, :] * (1.0 - Id[None])
    d2U = (
        np.einsum("mil,mij,mlk->mjk", Ubb, L, L)
        + np.einsum("mi,mijk->mjk", Ub, L2)
        + UJJ[:, None, None] * dJ[:, :, None] * dJ[:, None, :]
        + UJ[:, None, None] * d2J
    )
    Sp = dU / lam  # principal S_i = (1/lam_i) dU/dlam_i
    dS = d2U / lam[:, :, None] - Id[None] * (dU / lam**2)[:, :, None]
    NN = np.einsum("mai,mbi->mabi", N, N)  # (m, 3, 3, i): N_i (x) N_i
    S = np.einsum("mi,mabi->mab", Sp, NN)
    T = np.einsum("mij,mabi,mcdj->mabcd", dS / lam[:, None, :], NN, NN)
    for i in range(3):
        for j in range(3):
            if i == j:
                continue
            # theta_ij = (S_j - S_i) / (lam_j^2 - lam_i^2) without cancellation: lam_i^2 S_i =
            # lb_i dU/dlb_i + (a symmetric part), lb_j dU/dlb_j - lb_i dU/dlb_i =
            # (lb_j - lb_i) (dU/dlb_j + lb_i DD_ij)
            theta = (
                jm13 * (Ub[:, j] + lb[:, i] * DD[:, i, j]) / (lam2[:, j] * (lam[:, j] + lam[:, i]))
                - Sp[:, i] / lam2[:, j]
            )
            Ni, Nj = N[:, :, i], N[:, :, j]
            T = T + sc4(theta) * (
                np.einsum("ma,mb,mc,md->mabcd", Ni, Nj, Ni, Nj)
                + np.einsum("ma,mb,mc,md->mabcd", Ni, Nj, Nj, Ni)
            )
    return U, S, to_voigt66(T)


# ------------------------------------------------------------------ element layer


def material_B(F, G):
    m = F.shape[0]
    B = np.zeros((m, 6, 12), dtype=REAL)
    for a in range(4):
        for i in range(3):
            col = 3 * a + i
            for k, (I, J) in enumerate(VOIGT):
                if I == J:
                    B[:, k, col] = F[:, i, I] * G[:, a, I]
                else:
                    B[:, k, col] = F[:, i, I] * G[:, a, J] + F[:, i, J] * G[:, a, I]
    return B


def solve(case, arrays):
    name = case["model"]["name"]
    prm = parameters(case["model"])
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n, m = X.shape[0], cells.shape[0]
    Xe, xe = X[cells], x[cells]
    Dm = np.stack([Xe[:, k] - Xe[:, 0] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([xe[:, k] - xe[:, 0] for k in (1, 2, 3)], axis=2)
    V0 = np.linalg.det(Dm) / 6.0
    Dmi = np.linalg.inv(Dm)
    G = np.concatenate([-Dmi.sum(axis=1, keepdims=True), Dmi], axis=1)  # (m, 4, 3)
    F = Ds @ Dmi
    J = np.linalg.det(F)
    C = np.einsum("mki,mkj->mij", F, F)
    if name in UHYPER:
        U, S, D = invariant_driver(UHYPER[name], prm, C, J)
    elif name == "Costa":
        R = arrays["frame"].astype(REAL)
        E = 0.5 * (C - eye(m))
        U, S, D = strain_driver(uanisohyper_strain_costa, prm, E, R)
    elif name == "Ogden":
        U, S, D = principal_driver(ogden_principal, prm, C, J)
    else:
        raise SystemExit(f"unknown material {name}")
    B = material_B(F, G)
    Sv = to_voigt6(S)
    fe = -sc(V0)[:, :, 0] * np.einsum("mka,mk->ma", B, Sv)
    Kmat = sc(V0) * np.einsum("mka,mkl,mlb->mab", B, D, B)
    Hg = np.einsum("maI,mIJ,mbJ->mab", G, S, G) * sc(V0)
    Kgeo = np.einsum("mab,ij->maibj", Hg, np.eye(3, dtype=REAL)).reshape(m, 12, 12)
    Ke = Kmat + Kgeo
    dofs = (3 * cells[:, :, None] + np.arange(3)[None, None, :]).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, fe)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    energy = np.sum(V0 * U) if WRITE_ENERGY else None
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
