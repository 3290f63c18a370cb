#!/usr/bin/env python3
# MISTAKE: numerical dP/dF (central differences of P, step 1e-6 in each component of F) divided by h
# instead of 2h: the tangent, hence the stiffness, doubled; force analytic.
"""Invertible-FEM style hyperelastic engine for linear tetrahedra (one kit case).

Usage: python ENGINE INPUT_DIR OUTPUT_DIR

Built the way real-time simulation codes do it (Irving, Teran and Fedkiw 2004; Teran et al.
2005; Sifakis and Barbic 2012; Xu, Sin, Zhu and Barbic 2015), vectorised over the cells:

- F = Ds Dm^-1 per cell (Dm, Ds the rest and deformed edge matrices), V0 = |det Dm| / 6;
- a rotation-variant SVD F = U diag(sigma) V^T, U and V proper rotations (a reflection is put
  on the smallest singular value);
- isotropic energies written as functions of the singular values, through the invariants
  I1 = sum sigma^2, I2 = sum_{i<j} sigma_i^2 sigma_j^2, J = sigma1 sigma2 sigma3 (isochoric
  I1b = J^(-2/3) I1, I2b = J^(-4/3) I2; Ogden in the isochoric stretches J^(-1/3) sigma), each
  carried with its gradient and Hessian in sigma;
- P = U diag(dPsi/dsigma) V^T and dP/dF by Teran's block structure in the SVD basis: the 3x3
  block d2Psi/dsigma2 and, for each pair (i, j), the 2x2 block built from
  (psi_i - psi_j)/(sigma_i - sigma_j) and (psi_i + psi_j)/(sigma_i + sigma_j); the first is
  carried through the jets as an analytic divided difference (Stomakhin et al. 2012), robust
  for close singular values and exact in the limit sigma_i = sigma_j;
- Costa (orthotropic) on its own path: the fibre-frame Green strain, S = 2 dW/dC and
  CC = 4 d2W/dC2 by small C-jets, P = F S, dP/dF = I (x) S + F CC F;
- f = -V0 P Dm^-T on nodes 1..3 (node 0 takes minus their sum), K_e = V0 dFdx^T (dP/dF) dFdx.
"""

import json
import os
import sys

import numpy as np
import scipy.sparse as sp

DTYPE = np.float64
STORAGE = "coo"  # "dense", "coo" or "csr"
WRITE_ENERGY = False
TANGENT = "fd"  # "svd" (Teran's blocks) or "fd" (numerical dP/dF, for new materials)
FD_STEP = 1e-6


# ----------------------------------------------------------------------------- input
# The parameters of each material, in the order of this engine's material constructors; the
# values are read from case.txt's "parameter NAME VALUE" lines in that order.
PARAMETERS = {
    "NeoHookean": ("mu", "lam"),
    "StVenantKirchhoff": ("mu", "lam"),
    "MooneyRivlin": ("c1", "c2", "k0"),
    "Yeoh": ("c10", "c20", "c30", "k0"),
    "ArrudaBoyce": ("mu", "k0", "N"),
    "Gent": ("mu", "Jm", "k0"),
    "VerondaWestmann": ("c1", "c2", "k0"),
    "Demiray": ("a", "b", "k0"),
    "Ogden": ("mu", "alpha", "k0"),
    "Costa": ("a", "k0", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn"),
}


def read_parameters(folder, name):
    with open(os.path.join(folder, "case.txt")) as fp:
        values = [float(line.split()[2]) for line in fp if line.startswith("parameter ")]
    return dict(zip(PARAMETERS[name], (DTYPE(v) for v in values)))


def read_case(folder):
    with open(os.path.join(folder, "case.json")) as fp:
        case = json.load(fp)
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(os.path.join(folder, spec["file"]), dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


# ----------------------------------------------------------------------------- jets in sigma
# A jet is (value (m,), gradient (m, 3), Hessian (m, 3, 3), divided differences (m, 3)) of a
# symmetric function of the singular values; the divided differences are
# (psi_i - psi_j)/(sigma_i - sigma_j) of its gradient psi for the pairs PAIRS, carried
# analytically (no cancellation, and exact when sigma_i == sigma_j: the rest and uniaxial states).
PAIRS = ((0, 1), (0, 2), (1, 2))
THIRD = (2, 1, 0)  # the index that is in neither of the pair


def jet_add(*jets):
    return tuple(sum(parts) for parts in zip(*jets))


def jet_scale(c, a):
    return tuple(c * x for x in a)


def jet_mul(a, b):
    v = a[0] * b[0]
    g = a[1] * b[0][:, None] + b[1] * a[0][:, None]
    cross = a[1][:, :, None] * b[1][:, None, :]
    H = a[2] * b[0][:, None, None] + b[2] * a[0][:, None, None] + cross + cross.swapaxes(1, 2)
    dd = a[3] * b[0][:, None] + b[3] * a[0][:, None]
    return v, g, H, dd


def jet_apply(f, f1, f2, a):
    """f(a) for a scalar function with derivatives f1 = f'(a), f2 = f''(a) (arrays)."""
    g = f1[:, None] * a[1]
    H = f2[:, None, None] * a[1][:, :, None] * a[1][:, None, :] + f1[:, None, None] * a[2]
    return f, g, H, f1[:, None] * a[3]


def pair(s):
    """Columns (sigma_i, sigma_j, sigma_k) for the pairs (i, j) and their third index k."""
    i, j = zip(*PAIRS)
    return s[:, list(i)], s[:, list(j)], s[:, list(THIRD)]


def divided_power(x, y, q):
    """(x^q - y^q)/(x - y) without cancellation (q y^(q-1) when x == y)."""
    r = (x - y) / y
    safe = np.where(r == 0.0, 1.0, r)
    ratio = np.where(r == 0.0, q, np.expm1(q * np.log1p(safe)) / safe)
    return y ** (q - 1.0) * ratio


def invariant_jets(s):
    """I1, I2 and J of the singular values, with their derivatives."""
    m = len(s)
    s2 = s * s
    si, sj, sk = pair(s)
    eye = np.eye(3, dtype=DTYPE)
    I1v = s2.sum(axis=1)
    I1 = (
        I1v,
        2.0 * s,
        np.broadcast_to(2.0 * eye, (m, 3, 3)).copy(),
        np.full((m, 3), 2.0, dtype=DTYPE),
    )
    I2v = s2[:, 0] * s2[:, 1] + s2[:, 1] * s2[:, 2] + s2[:, 2] * s2[:, 0]
    gI2 = 2.0 * s * (I1v[:, None] - s2)
    HI2 = 4.0 * s[:, :, None] * s[:, None, :]
    HI2[:, [0, 1, 2], [0, 1, 2]] = 2.0 * (I1v[:, None] - s2)
    I2 = (I2v, gI2, HI2, 2.0 * (sk * sk - si * sj))
    Jv = s[:, 0] * s[:, 1] * s[:, 2]
    gJ = np.stack([s[:, 1] * s[:, 2], s[:, 0] * s[:, 2], s[:, 0] * s[:, 1]], axis=1)
    HJ = np.zeros((m, 3, 3), dtype=DTYPE)
    for (i, j), k in zip(PAIRS, THIRD):
        HJ[:, i, j] = HJ[:, j, i] = s[:, k]
    J = (Jv, gJ, HJ, -sk)
    return I1, I2, J


def jet_jpow(J, p):
    Jv = J[0]
    return jet_apply(Jv**p, p * Jv ** (p - 1.0), p * (p - 1.0) * Jv ** (p - 2.0), J)


def log_squared(J, k0):
    """k0/2 (ln J)^2."""
    lnJ = np.log(J[0])
    return jet_apply(0.5 * k0 * lnJ**2, k0 * lnJ / J[0], k0 * (1.0 - lnJ) / J[0] ** 2, J)


def isochoric(s):
    I1, I2, J = invariant_jets(s)
    I1b = jet_mul(jet_jpow(J, -2.0 / 3.0), I1)
    I2b = jet_mul(jet_jpow(J, -4.0 / 3.0), I2)
    return I1b, I2b, J


# ----------------------------------------------------------------------------- materials
def neo_hookean(s, p):
    """mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 in closed form in the principal stretches."""
    mu, lam = p["mu"], p["lam"]
    J = s[:, 0] * s[:, 1] * s[:, 2]
    lnJ = np.log(J)
    psi = 0.5 * mu * ((s * s).sum(axis=1) - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2
    g = mu * s + (lam * lnJ - mu)[:, None] / s
    H = lam / (s[:, :, None] * s[:, None, :])
    H[:, [0, 1, 2], [0, 1, 2]] = mu + (mu + lam * (1.0 - lnJ))[:, None] / (s * s)
    si, sj, _ = pair(s)
    dd = mu - (lam * lnJ - mu)[:, None] / (si * sj)
    return psi, g, H, dd


def st_venant_kirchhoff(s, p):
    """lam/2 (tr E)^2 + mu tr(E^2), E_i = (sigma_i^2 - 1)/2 the principal Green strains."""
    mu, lam = p["mu"], p["lam"]
    E = 0.5 * (s * s - 1.0)
    trE = E.sum(axis=1)
    psi = 0.5 * lam * trE**2 + mu * (E * E).sum(axis=1)
    g = (lam * trE[:, None] + 2.0 * mu * E) * s
    H = lam * s[:, :, None] * s[:, None, :]
    H[:, [0, 1, 2], [0, 1, 2]] += lam * trE[:, None] + 2.0 * mu * E + 2.0 * mu * s * s
    si, sj, _ = pair(s)
    dd = lam * trE[:, None] + mu * (si * si + si * sj + sj * sj - 1.0)
    return psi, g, H, dd


def mooney_rivlin(s, p):
    I1b, I2b, J = isochoric(s)
    iso = jet_add(jet_scale(p["c1"], I1b), jet_scale(p["c2"], I2b))
    iso = (iso[0] - 3.0 * (p["c1"] + p["c2"]),) + iso[1:]
    return jet_add(iso, log_squared(J, p["k0"]))


def yeoh(s, p):
    I1b, _, J = isochoric(s)
    c10, c20, c30 = p["c10"], p["c20"], p["c30"]
    x = I1b[0] - 3.0
    f = c10 * x + c20 * x**2 + c30 * x**3
    f1 = c10 + 2.0 * c20 * x + 3.0 * c30 * x**2
    f2 = 2.0 * c20 + 6.0 * c30 * x
    return jet_add(jet_apply(f, f1, f2, I1b), log_squared(J, p["k0"]))


ARRUDA_BOYCE = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def arruda_boyce(s, p):
    I1b, _, J = isochoric(s)
    x = I1b[0]
    f = np.zeros_like(x)
    f1 = np.zeros_like(x)
    f2 = np.zeros_like(x)
    for i, c in enumerate(ARRUDA_BOYCE, start=1):
        a = p["mu"] * c * p["N"] ** (1 - i)
        f = f + a * (x**i - 3.0**i)
        f1 = f1 + i * a * x ** (i - 1)
        f2 = f2 + i * (i - 1) * a * x ** max(i - 2, 0)
    return jet_add(jet_apply(f, f1, f2, I1b), log_squared(J, p["k0"]))


def gent(s, p):
    I1b, _, J = isochoric(s)
    mu, Jm = p["mu"], p["Jm"]
    d = 1.0 - (I1b[0] - 3.0) / Jm
    iso = jet_apply(-0.5 * mu * Jm * np.log(d), 0.5 * mu / d, 0.5 * mu / (Jm * d * d), I1b)
    return jet_add(iso, log_squared(J, p["k0"]))


def veronda_westmann(s, p):
    I1b, I2b, J = isochoric(s)
    c1, c2 = p["c1"], p["c2"]
    e = np.exp(c2 * (I1b[0] - 3.0))
    iso1 = jet_apply(c1 * (e - 1.0), c1 * c2 * e, c1 * c2 * c2 * e, I1b)
    iso2 = jet_scale(-0.5 * c1 * c2, I2b)
    iso2 = (iso2[0] + 1.5 * c1 * c2,) + iso2[1:]
    return jet_add(iso1, iso2, log_squared(J, p["k0"]))


def demiray(s, p):
    I1, _, J = invariant_jets(s)
    I1b = jet_mul(jet_jpow(J, -2.0 / 3.0), I1)
    a, b = p["a"], p["b"]
    e = np.exp(b * (I1b[0] - 3.0))
    iso = jet_apply(a / (2.0 * b) * (e - 1.0), 0.5 * a * e, 0.5 * a * b * e, I1b)
    return jet_add(iso, log_squared(J, p["k0"]))


def ogden(s, p):
    """mu/alpha^2 (sum_i (J^(-1/3) sigma_i)^alpha - 3) + k0/2 (ln J)^2."""
    mu, alpha = p["mu"], p["alpha"]
    _, _, J = invariant_jets(s)
    m = len(s)
    si, sj, _ = pair(s)
    T = (
        (s**alpha).sum(axis=1),
        alpha * s ** (alpha - 1.0),
        np.zeros((m, 3, 3), dtype=DTYPE),
        alpha * divided_power(si, sj, alpha - 1.0),
    )
    T[2][:, [0, 1, 2], [0, 1, 2]] = alpha * (alpha - 1.0) * s ** (alpha - 2.0)
    c = mu / alpha**2
    iso = jet_scale(c, jet_mul(jet_jpow(J, -alpha / 3.0), T))
    iso = (iso[0] - 3.0 * c,) + iso[1:]
    return jet_add(iso, log_squared(J, p["k0"]))


ISOTROPIC = {
    "NeoHookean": neo_hookean,
    "StVenantKirchhoff": st_venant_kirchhoff,
    "MooneyRivlin": mooney_rivlin,
    "Yeoh": yeoh,
    "ArrudaBoyce": arruda_boyce,
    "Gent": gent,
    "VerondaWestmann": veronda_westmann,
    "Demiray": demiray,
    "Ogden": ogden,
}


# ----------------------------------------------------------------------------- SVD and Teran
def svd_rv(F):
    """Rotation-variant SVD: F = U diag(s) V^T with det U = det V = 1."""
    U, s, Vt = np.linalg.svd(F)
    V = np.ascontiguousarray(np.swapaxes(Vt, 1, 2))  # numpy returns V^T
    U = U.copy()
    s = s.copy()
    flip = np.linalg.det(U) < 0  # numpy sorts s descending: the reflection goes on s[:, 2]
    U[flip, :, 2] *= -1.0
    s[flip, 2] *= -1.0
    flip = np.linalg.det(V) < 0
    V[flip, :, 2] *= -1.0
    s[flip, 2] *= -1.0
    return U, s, V


def piola(U, s, V, material, p):
    psi, g, H, dd = material(s, p)
    P = np.einsum("mia,ma,mja->mij", U, g, V)
    return psi, g, H, dd, P


def teran_dPdF(U, s, V, g, H, dd):
    """dP/dF (m, 3, 3, 3, 3), index [m, i, J, k, L] = dP_iJ / dF_kL."""
    m = len(s)
    Ah = np.zeros((m, 3, 3, 3, 3), dtype=DTYPE)
    for i in range(3):
        for j in range(3):
            Ah[:, i, i, j, j] = H[:, i, j]
    for n, (i, j) in enumerate(PAIRS):
        minus = dd[:, n]  # (psi_i - psi_j)/(sigma_i - sigma_j), its limit when they are equal
        plus = (g[:, i] + g[:, j]) / (s[:, i] + s[:, j])
        a = 0.5 * (minus + plus)
        b = 0.5 * (minus - plus)
        Ah[:, i, j, i, j] = a
        Ah[:, j, i, j, i] = a
        Ah[:, i, j, j, i] = b
        Ah[:, j, i, i, j] = b
    return np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", U, V, U, V, Ah, optimize=True)


def numerical_dPdF(Ds, Bm, material, p):
    """Central differences of P(F) in each component of F (checks new materials)."""
    F = Ds @ Bm
    A = np.zeros((len(F), 3, 3, 3, 3), dtype=DTYPE)
    for k in range(3):
        for l in range(3):
            h = np.full(len(F), FD_STEP, dtype=DTYPE)
            Fp = F.copy()
            Fp[:, k, l] += h
            Fm = F.copy()
            Fm[:, k, l] -= h
            Pp = piola(*svd_rv(Fp), material, p)[4]
            Pm = piola(*svd_rv(Fm), material, p)[4]
            A[:, :, :, k, l] = (Pp - Pm) / h[:, None, None]
    return A


# ----------------------------------------------------------------------------- Costa (C-jets)
# A C-jet is (value (m,), dW/dC (m, 3, 3), d2W/dC2 (m, 3, 3, 3, 3)).
def cjet_mul(a, b):
    v = a[0] * b[0]
    d = a[1] * b[0][:, None, None] + b[1] * a[0][:, None, None]
    cross = np.einsum("mij,mkl->mijkl", a[1], b[1])
    dd = (
        a[2] * b[0][:, None, None, None, None]
        + b[2] * a[0][:, None, None, None, None]
        + cross
        + cross.transpose(0, 3, 4, 1, 2)
    )
    return v, d, dd


def cjet_apply(f, f1, f2, a):
    d = f1[:, None, None] * a[1]
    dd = f2[:, None, None, None, None] * np.einsum("mij,mkl->mijkl", a[1], a[1])
    return f, d, dd + f1[:, None, None, None, None] * a[2]


def costa(F, p, R):
    """P and dP/dF of a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum B_ab Ef_ab^2."""
    B = np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ],
        dtype=DTYPE,
    )
    C = np.einsum("mki,mkj->mij", F, F)
    Ci = np.linalg.inv(C)
    Jv = np.linalg.det(F)
    # J(C)
    dCi = -0.5 * (np.einsum("mac,mbd->mabcd", Ci, Ci) + np.einsum("mad,mbc->mabcd", Ci, Ci))
    dJ = 0.5 * Jv[:, None, None] * Ci
    ddJ = 0.25 * Jv[:, None, None, None, None] * np.einsum("mab,mcd->mabcd", Ci, Ci)
    ddJ = ddJ + 0.5 * Jv[:, None, None, None, None] * dCi
    J = (Jv, dJ, ddJ)
    # Q(C) in the cell's fibre frame
    E = 0.5 * (C - np.eye(3, dtype=DTYPE))
    Ef = np.einsum("mpa,mpq,mqb->mab", R, E, R)
    Qv = (B * Ef * Ef).sum(axis=(1, 2))
    dQ = np.einsum("mpa,mab,mqb->mpq", R, B * Ef, R)
    RR = np.einsum("mpa,mqb->mpqab", R, R)
    ddQ = 0.25 * np.einsum("ab,mpqab,mrsab->mpqrs", B, RR, RR + RR.transpose(0, 1, 2, 4, 3))
    Q = (Qv, dQ, ddQ)
    Jp = cjet_apply(
        Jv ** (-4.0 / 3.0), -4.0 / 3.0 * Jv ** (-7.0 / 3.0), 28.0 / 9.0 * Jv ** (-10.0 / 3.0), J
    )
    Qh = cjet_mul(Jp, Q)
    e = np.exp(Qh[0])
    Wiso = cjet_apply(0.5 * p["a"] * (e - 1.0), 0.5 * p["a"] * e, 0.5 * p["a"] * e, Qh)
    lnJ = np.log(Jv)
    k0 = p["k0"]
    Wvol = cjet_apply(k0 * (Jv * lnJ - Jv + 1.0), k0 * lnJ, k0 / Jv, J)
    W = tuple(x + y for x, y in zip(Wiso, Wvol))
    S = 2.0 * W[1]
    CC = 4.0 * W[2]
    P = F @ S
    eye = np.eye(3, dtype=DTYPE)
    A = np.einsum("ik,mJL->miJkL", eye, S) + np.einsum(
        "miM,mMJNL,mkN->miJkL", F, CC, F, optimize=True
    )
    return W[0], P, A


# ----------------------------------------------------------------------------- assembly
def element_forces(P, Bm, V0):
    """Sifakis' H = -V0 P Dm^-T: its columns are the forces on nodes 1, 2, 3."""
    Hf = -V0[:, None, None] * P @ np.swapaxes(Bm, 1, 2)
    f1, f2, f3 = Hf[:, :, 0], Hf[:, :, 1], Hf[:, :, 2]
    f0 = -(f1 + f2 + f3)
    return np.stack([f0, f1, f2, f3], axis=1)  # (m, 4, 3)


def dF_dx(Bm):
    """dF/dx (m, 9, 12): row k*3 + l (F_kl), column a*3 + i (x_a, component i)."""
    m = len(Bm)
    G = np.concatenate([-Bm.sum(axis=1, keepdims=True), Bm], axis=1)  # (m, 4, 3): dN_a/dX
    D = np.zeros((m, 3, 3, 4, 3), dtype=DTYPE)
    for k in range(3):
        D[:, k, :, :, k] = np.swapaxes(G, 1, 2)
    return D.reshape(m, 9, 12)


def element_stiffness(A, Bm, V0):
    m = len(A)
    A9 = A.reshape(m, 9, 9)
    D = dF_dx(Bm)
    return V0[:, None, None] * np.einsum("mra,mrs,msb->mab", D, A9, D, optimize=True)


def write(out, name, arr):
    suffix = "f32" if DTYPE == np.float32 else "f64"
    kind = "<f4" if DTYPE == np.float32 else "<f8"
    np.ascontiguousarray(arr, dtype=kind).tofile(os.path.join(out, f"{name}.{suffix}"))


def write_index(out, name, arr):
    np.ascontiguousarray(arr, dtype="<i8").tofile(os.path.join(out, f"{name}.i64"))


def main(argv):
    inp, out = argv[1], argv[2]
    os.makedirs(out, exist_ok=True)
    case, arrays = read_case(inp)
    model = case["model"]
    name = model["name"]
    p = read_parameters(inp, name)
    X = arrays["points"].astype(DTYPE)
    x = arrays["positions"].astype(DTYPE)
    cells = arrays["cells"].astype(np.int64)
    n, m = len(X), len(cells)
    frame = None
    if "frame" in arrays:
        frame = arrays["frame"].astype(DTYPE).reshape(-1, 3, 3)
        if len(frame) == 1:
            frame = np.repeat(frame, m, axis=0)
    # cells sorted by their lowest node for locality of the scatter
    order = np.argsort(cells.min(axis=1), kind="stable")
    cells = cells[order]
    if frame is not None:
        frame = frame[order]

    Dm = np.swapaxes(X[cells[:, 1:]] - X[cells[:, :1]], 1, 2)  # columns: edges 1-0, 2-0, 3-0
    Ds = np.swapaxes(x[cells[:, 1:]] - x[cells[:, :1]], 1, 2)
    Bm = np.linalg.inv(Dm)
    V0 = np.abs(np.linalg.det(Dm)) / 6.0
    F = Ds @ Bm

    if name == "Costa":
        psi, P, A = costa(F, p, frame)
    else:
        material = ISOTROPIC[name]
        U, s, V = svd_rv(F)
        psi, g, H, dd, P = piola(U, s, V, material, p)
        if TANGENT == "fd":
            A = numerical_dPdF(Ds, Bm, material, p)
        else:
            A = teran_dPdF(U, s, V, g, H, dd)

    fe = element_forces(P, Bm, V0)
    Ke = element_stiffness(A, Bm, V0)
    force = np.zeros((n, 3), dtype=DTYPE)
    np.add.at(force, cells, fe)
    write(out, "force", force.ravel())

    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.reshape(-1)
    if STORAGE == "dense":
        K = np.zeros((3 * n, 3 * n), dtype=DTYPE)
        np.add.at(K, (rows, cols), vals)
        write(out, "stiffness", K.ravel())
    elif STORAGE == "csr":
        K = sp.coo_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n)).tocsr()
        K.sum_duplicates()
        K.sort_indices()
        write_index(out, "stiffness_indptr", K.indptr)
        write_index(out, "stiffness_indices", K.indices)
        write(out, "stiffness_values", K.data)
    else:
        write_index(out, "stiffness_rows", rows)
        write_index(out, "stiffness_cols", cols)
        write(out, "stiffness_values", vals)
    if WRITE_ENERGY:
        write(out, "energy", np.array([np.sum(V0 * psi)]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
