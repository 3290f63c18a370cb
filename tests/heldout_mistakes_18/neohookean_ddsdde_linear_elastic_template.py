#!/usr/bin/env python3
# MISTAKE: Neo-Hookean UMAT's DDSDDE taken from the linear-elastic template, lam I (x) I + 2 mu I4
# (the tangent at rest) plus the Jaumann-rate terms, where lam/J I (x) I + 2 (mu - lam ln J)/J I4
# belongs: stiffness wrong wherever J != 1 (both states); force and energy right.
"""P1 tetrahedral hyperelastic engine, Abaqus UMAT style.

Per cell: F = Ds Dm^-1, J, b = F F^T; a UMAT-like constitutive routine returns the Cauchy
stress in Voigt form (Abaqus order 11, 22, 33, 12, 13, 23) and the material Jacobian DDSDDE
(Jaumann-rate tangent of the Kirchhoff stress over J, engineering shear strains); the element
converts DDSDDE to the Truesdell (Cauchy-based spatial) tangent D, and assembles
K_e = v B^T D B + K_geo, f_e = -v B^T sigma, v = J V0 with the spatial B matrix (6 x 12).

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

# Abaqus Voigt order: 11, 22, 33, 12, 13, 23
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


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


def dyad(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def sdyad(A, B):
    # (A_ik B_jl + A_il B_jk) / 2
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def trace(A):
    return np.einsum("mii->m", A)


def dev(A):
    return A - trace(A)[:, None, None] / 3.0 * eye(A.shape[0])


def s(x):
    return x[:, None, None]


def t(x):
    return x[:, None, None, None, None]


def to_voigt(A):
    return np.stack([A[:, i, j] for i, j in VOIGT], axis=1)


def to_voigt66(C):
    D = np.empty((C.shape[0], 6, 6), dtype=REAL)
    for a, (i, j) in enumerate(VOIGT):
        for b, (k, l) in enumerate(VOIGT):
            D[:, a, b] = C[:, i, j, k, l]
    return D


def jaumann_terms(sig):
    # 1/2 (d_ik s_jl + d_il s_jk + s_ik d_jl + s_il d_jk), as a 6 x 6 matrix
    Id = eye(sig.shape[0])
    return to_voigt66(sdyad(Id, sig) + sdyad(sig, Id))


# ------------------------------------------------------------------ UMATs
# each returns (sigma (m, 3, 3), DDSDDE (m, 6, 6), W (m,))


def uncoupled_umat(J, b, W1, W2, W11, W12, W22, k0):
    m = J.shape[0]
    Id = eye(m)
    bb = s(J ** (-2.0 / 3.0)) * b
    I1b = trace(bb)
    bb2 = bb @ bb
    d = s(I1b) * bb - bb2
    sb = s(2.0 / J) * (s(W1) * bb + s(W2) * d)
    cb = t(4.0 / J) * (
        t(W11) * dyad(bb, bb)
        + t(W12) * (dyad(bb, d) + dyad(d, bb))
        + t(W22) * dyad(d, d)
        + t(W2) * (dyad(bb, bb) - sdyad(bb, bb))
    )
    I4 = sdyad(Id, Id)
    P = I4 - dyad(Id, Id) / 3.0
    PcP = np.einsum("mijpq,mpqrs,mrskl->mijkl", P, cb, P)
    sdev = dev(sb)
    c_iso = PcP + t(2.0 / 3.0 * trace(sb)) * P - 2.0 / 3.0 * (dyad(sdev, Id) + dyad(Id, sdev))
    p = k0 * np.log(J) / J
    sig = sdev + s(p) * Id
    # Jaumann tangent: isochoric Truesdell part plus its rate terms; volumetric part
    # (p + J dp/dJ) I (x) I (its -2 p I4 and rate terms cancel)
    ddsdde = to_voigt66(c_iso) + jaumann_terms(sdev)
    ddsdde = ddsdde + s(k0 / J) * to_voigt66(dyad(Id, Id))
    return sig, ddsdde


def log_volumetric_energy(J, k0):
    return 0.5 * k0 * np.log(J) ** 2


def invariants_bar(J, b):
    bb = s(J ** (-2.0 / 3.0)) * b
    I1b = trace(bb)
    I2b = 0.5 * (I1b**2 - trace(bb @ bb))
    return I1b, I2b


def mooney_rivlin(prm, J, b):
    z = np.zeros_like(J)
    I1b, I2b = invariants_bar(J, b)
    c1, c2, k0 = prm["c1"], prm["c2"], prm["k0"]
    sig, D = uncoupled_umat(J, b, z + c1, z + c2, z, z, z, k0)
    W = c1 * (I1b - 3.0) + c2 * (I2b - 3.0) + log_volumetric_energy(J, k0)
    return sig, D, W


def veronda_westmann(prm, J, b):
    z = np.zeros_like(J)
    I1b, I2b = invariants_bar(J, b)
    c1, c2, k0 = prm["c1"], prm["c2"], prm["k0"]
    e = np.exp(c2 * (I1b - 3.0))
    W1 = c1 * c2 * e
    W11 = c1 * c2**2 * e
    W2 = z - 0.5 * c1 * c2
    sig, D = uncoupled_umat(J, b, W1, W2, W11, z, z, k0)
    W = c1 * (e - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0) + log_volumetric_energy(J, k0)
    return sig, D, W


AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def arruda_boyce(prm, J, b):
    z = np.zeros_like(J)
    I1b, _ = invariants_bar(J, b)
    mu, k0, N = prm["mu"], prm["k0"], prm["N"]
    W1 = z.copy()
    W11 = z.copy()
    Wi = z.copy()
    for i in range(1, 6):
        ci = AB_C[i - 1] * N ** (1 - i)
        Wi = Wi + mu * ci * (I1b**i - 3.0**i)
        W1 = W1 + mu * ci * i * I1b ** (i - 1)
        if i > 1:
            W11 = W11 + mu * ci * i * (i - 1) * I1b ** (i - 2)
    sig, D = uncoupled_umat(J, b, W1, z, W11, z, z, k0)
    return sig, D, Wi + log_volumetric_energy(J, k0)


def yeoh(prm, J, b):
    z = np.zeros_like(J)
    I1b, _ = invariants_bar(J, b)
    c10, c20, c30, k0 = prm["c10"], prm["c20"], prm["c30"], prm["k0"]
    x = I1b - 3.0
    W1 = c10 + 2.0 * c20 * x + 3.0 * c30 * x**2
    W11 = 2.0 * c20 + 6.0 * c30 * x
    sig, D = uncoupled_umat(J, b, W1, z, W11, z, z, k0)
    W = c10 * x + c20 * x**2 + c30 * x**3 + log_volumetric_energy(J, k0)
    return sig, D, W


def gent(prm, J, b):
    z = np.zeros_like(J)
    I1b, _ = invariants_bar(J, b)
    mu, k0, Jm = prm["mu"], prm["k0"], prm["Jm"]
    g = 1.0 - (I1b - 3.0) / Jm
    W1 = 0.5 * mu / g
    W11 = 0.5 * mu / (Jm * g**2)
    sig, D = uncoupled_umat(J, b, W1, z, W11, z, z, k0)
    W = -0.5 * mu * Jm * np.log(g) + log_volumetric_energy(J, k0)
    return sig, D, W


def demiray(prm, J, b):
    z = np.zeros_like(J)
    I1b, _ = invariants_bar(J, b)
    a, bd, k0 = prm["a"], prm["b"], prm["k0"]
    e = np.exp(bd * (I1b - 3.0))
    W1 = 0.5 * a * e
    W11 = 0.5 * a * bd * e
    sig, D = uncoupled_umat(J, b, W1, z, W11, z, z, k0)
    W = a / (2.0 * bd) * np.expm1(bd * (I1b - 3.0)) + log_volumetric_energy(J, k0)
    return sig, D, W


def neo_hookean(prm, J, b):
    mu, lam = prm["mu"], prm["lam"]
    Id = eye(J.shape[0])
    lnJ = np.log(J)
    sig = s(mu / J) * (b - Id) + s(lam * lnJ / J) * Id
    c = lam * dyad(Id, Id) + 2.0 * mu * sdyad(Id, Id)
    D = to_voigt66(c) + jaumann_terms(sig)
    W = 0.5 * mu * (trace(b) - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2
    return sig, D, W


def st_venant_kirchhoff(prm, J, b):
    mu, lam = prm["mu"], prm["lam"]
    trE = 0.5 * (trace(b) - 3.0)
    b2 = b @ b
    sig = (s(lam * trE) * b + mu * (b2 - b)) / s(J)
    c = (lam * dyad(b, b) + 2.0 * mu * sdyad(b, b)) / t(J)
    D = to_voigt66(c) + jaumann_terms(sig)
    trE2 = 0.25 * (trace(b2) - 2.0 * trace(b) + 3.0)
    W = 0.5 * lam * trE**2 + mu * trE2
    return sig, D, W


def ogden(prm, J, b):
    mu, alpha, k0 = prm["mu"], prm["alpha"], prm["k0"]
    m = J.shape[0]
    Id = eye(m)
    lam2, n = np.linalg.eigh(b)  # squared principal stretches, directions as columns
    ll = 0.5 * np.log(lam2)  # ln lambda_a
    llb = ll - np.log(J)[:, None] / 3.0
    pa = np.exp(alpha * llb)  # lambda_bar_a^alpha
    S = pa.sum(axis=1)
    tau = mu / alpha * (pa - S[:, None] / 3.0)
    sa = tau / J[:, None]
    N = np.einsum("mia,mja->maij", n, n)  # n_a (x) n_a
    c = np.zeros((m, 3, 3, 3, 3), dtype=REAL)
    for a in range(3):
        for bq in range(3):
            dtau = mu * (pa[:, a] * (a == bq) - (pa[:, a] + pa[:, bq]) / 3.0 + S / 9.0)
            c += t(dtau / J) * dyad(N[:, a], N[:, bq])
        c -= t(2.0 * sa[:, a]) * dyad(N[:, a], N[:, a])
    for a in range(3):
        for bq in range(3):
            if a == bq:
                continue
            dl = ll[:, a] - ll[:, bq]
            small = np.abs(dl) < 1e-8
            dls = np.where(small, 1.0, dl)
            r = np.where(
                small, 0.5 * (alpha - 2.0), np.expm1((alpha - 2.0) * dls) / np.expm1(2.0 * dls)
            )
            G = (
                mu
                / alpha
                * (
                    lam2[:, a] * np.exp((alpha - 2.0) * ll[:, bq]) * J ** (-alpha / 3.0) * r
                    + S / 3.0
                )
                / J
            )
            nab = np.einsum("mi,mj->mij", n[:, :, a], n[:, :, bq])
            nba = np.einsum("mi,mj->mij", n[:, :, bq], n[:, :, a])
            c += t(G) * (dyad(nab, nab) + dyad(nab, nba))
    sdev = np.einsum("ma,maij->mij", sa, N)
    p = k0 * np.log(J) / J
    sig = sdev + s(p) * Id
    D = to_voigt66(c) + jaumann_terms(sdev) + s(k0 / J) * to_voigt66(dyad(Id, Id))
    W = mu / alpha**2 * (S - 3.0) + log_volumetric_energy(J, k0)
    return sig, D, W


COSTA_B = (
    ("b_ff", 0, 0),
    ("b_fs", 0, 1),
    ("b_ss", 1, 1),
    ("b_fn", 0, 2),
    ("b_sn", 1, 2),
    ("b_nn", 2, 2),
)


def costa(prm, J, F, frame):
    m = J.shape[0]
    Id = eye(m)
    Bm = np.zeros((3, 3), dtype=REAL)
    for name, i, j in COSTA_B:
        Bm[i, j] = Bm[j, i] = prm[name]
    a0, k0 = prm["a"], prm["k0"]
    R = frame
    C = np.einsum("mki,mkj->mij", F, F)
    E = 0.5 * (C - Id)
    Ef = np.einsum("mai,mab,mbj->mij", R, E, R)
    Q = np.einsum("ij,mij->m", Bm, Ef**2)
    Jq = J ** (-4.0 / 3.0)
    q = Jq * Q
    A = F @ R  # a_i = F r_i as columns
    BE = Bm[None] * Ef
    mm = np.einsum("mij,mpi,mqj->mpq", BE, A, A)
    mm = 0.5 * (mm + np.swapaxes(mm, 1, 2))
    dq = s(Jq) * (mm - 2.0 / 3.0 * s(Q) * Id)
    eq = np.exp(q)
    sig_iso = s(a0 * eq / J) * dq
    nn = np.zeros((m, 3, 3, 3, 3), dtype=REAL)
    for i in range(3):
        for j in range(3):
            nij = 0.5 * (
                np.einsum("mp,mq->mpq", A[:, :, i], A[:, :, j])
                + np.einsum("mp,mq->mpq", A[:, :, j], A[:, :, i])
            )
            nn += Bm[i, j] * dyad(nij, nij)
    d2q = t(Jq) * (
        0.5 * nn
        - 2.0 / 3.0 * (dyad(mm, Id) + dyad(Id, mm))
        + t(4.0 / 9.0 * Q) * dyad(Id, Id)
        + t(2.0 / 3.0 * Q) * sdyad(Id, Id)
    )
    c_iso = t(2.0 * a0 * eq / J) * (dyad(dq, dq) + d2q)
    p = k0 * np.log(J)
    sig = sig_iso + s(p) * Id
    D = to_voigt66(c_iso) + jaumann_terms(sig_iso) + s(p + k0) * to_voigt66(dyad(Id, Id))
    W = 0.5 * a0 * np.expm1(q) + k0 * (J * np.log(J) - J + 1.0)
    return sig, D, W


def umat(name, prm, J, F, b, arrays):
    if name == "Costa":
        return costa(prm, J, F, arrays["frame"].astype(REAL))
    table = {
        "NeoHookean": neo_hookean,
        "StVenantKirchhoff": st_venant_kirchhoff,
        "MooneyRivlin": mooney_rivlin,
        "VerondaWestmann": veronda_westmann,
        "ArrudaBoyce": arruda_boyce,
        "Yeoh": yeoh,
        "Gent": gent,
        "Demiray": demiray,
        "Ogden": ogden,
    }
    return table[name](prm, J, b)


# ------------------------------------------------------------------ element


def spatial_B(g):
    # g (m, 4, 3) spatial gradients; B (m, 6, 12), engineering shear rows, Abaqus order
    m = g.shape[0]
    B = np.zeros((m, 6, 12), dtype=REAL)
    for a in range(4):
        gx, gy, gz = g[:, a, 0], g[:, a, 1], g[:, a, 2]
        B[:, 0, 3 * a] = gx
        B[:, 1, 3 * a + 1] = gy
        B[:, 2, 3 * a + 2] = gz
        B[:, 3, 3 * a] = gy
        B[:, 3, 3 * a + 1] = gx
        B[:, 4, 3 * a] = gz
        B[:, 4, 3 * a + 2] = gx
        B[:, 5, 3 * a + 1] = gz
        B[:, 5, 3 * a + 2] = gy
    return B


def solve(case, arrays):
    name = case["model"]["name"]
    prm = parameters(case["model"])
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n = X.shape[0]
    m = cells.shape[0]

    Dm = np.stack([X[cells[:, k]] - X[cells[:, 0]] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([x[cells[:, k]] - x[cells[:, 0]] for k in (1, 2, 3)], axis=2)
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)
    G = np.zeros((m, 4, 3), dtype=REAL)
    G[:, 1:, :] = Dinv
    G[:, 0, :] = -Dinv.sum(axis=1)

    F = Ds @ Dinv
    J = np.linalg.det(F)
    b = F @ np.swapaxes(F, 1, 2)
    Finv = np.linalg.inv(F)
    g = G @ Finv  # spatial gradients as rows
    v = J * V0

    sig, ddsdde, W = umat(name, prm, J, F, b, arrays)
    stress = to_voigt(sig)
    # Jaumann (DDSDDE) -> Truesdell tangent of the Cauchy stress
    D = ddsdde - jaumann_terms(sig)

    B = spatial_B(g)
    fe = -s(v)[:, :, 0] * np.einsum("mai,ma->mi", B, stress)
    Ke = s(v) * np.einsum("mai,mab,mbj->mij", B, D, B)
    geo = np.einsum("mai,mij,mbj->mab", g, sig, g)  # g_a . sigma . g_b
    Kg = np.einsum("mab,ik->maibk", geo, np.eye(3, dtype=REAL)).reshape(m, 12, 12)
    Ke = Ke + s(v) * Kg

    dofs = (3 * cells[:, :, None] + np.arange(3)[None, None, :]).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, fe)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.ravel()
    energy = np.sum(V0 * W) if WRITE_ENERGY else None
    return force.reshape(n, 3), (rows, cols, vals, 3 * n), energy


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
