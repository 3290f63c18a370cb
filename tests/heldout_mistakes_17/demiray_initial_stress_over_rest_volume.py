#!/usr/bin/env python3
# MISTAKE: initial-stress (geometric) part of the stiffness integrated over the rest volume, V0
# (grad N_a . sigma grad N_b) I, while the material part and the force use v = J V0: stiffness
# wrong in both states; force right (no energy written).
"""P1 tetrahedral hyperelastic engine in the FEBio style: spatial (updated Lagrangian) form.

Vectorised over the m cells with NumPy (no Python loop over cells). From the rest edge matrix
Dm = [X1 - X0, X2 - X0, X3 - X0]: the material shape-function gradients G_a (rows of Dm^-1,
G_0 = -(G_1 + G_2 + G_3)) and V0 = det(Dm) / 6. At the current state: F = Ds Dm^-1, J = det F,
the deformed volume v = J V0, the spatial gradients g_a = F^-T G_a, b = F F^T. Each material gives
its Cauchy stress sigma and its spatial elasticity tensor c (full 3x3x3x3, Cauchy-based, the
Truesdell rate's tangent). Decoupled materials follow FEBio's uncoupled split: the fictitious
Cauchy stress sigma_bar and tangent c_bar from W_iso(b_bar), sigma = dev(sigma_bar) + p I,
c = P:c_bar:P + 2/3 tr(sigma_bar) P - 2/3 (sigma_dev (x) I + I (x) sigma_dev)
+ (p + J dp/dJ) I (x) I - 2 p I4, P = I4 - 1/3 I (x) I; Ogden through its spectral (principal
stretch) form; Costa's fibre frame pushed forward (a_i = F r_i). Internal force f_a = -v sigma g_a,
stiffness K_ab = v [g_a . c . g_b + (g_a . sigma . g_b) I] (material + initial-stress parts),
assembled node-major (dof 3 node + component) into a dense, COO or CSR stiffness; energy
sum V0 W.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one exported mjed-verify kit case).
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "csr"
WRITE_ENERGY = False
AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


def parameters(model):
    p = {k: REAL(v) for k, v in model["parameters"].items()}
    return p


# ------------------------------------------------------------------ tensor helpers
# second-order tensors (m, 3, 3), fourth-order tensors (m, 3, 3, 3, 3)


def eye(m):
    return np.broadcast_to(np.eye(3, dtype=REAL), (m, 3, 3))


def dyad(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def sdyad(A, B):
    """(A (.) B)_ijkl = (A_ik B_jl + A_il B_jk) / 2."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def trace(A):
    return np.einsum("mii->m", A)


def dev(A):
    return A - (trace(A) / 3.0)[:, None, None] * eye(A.shape[0])


def s(x):
    """Scalar per cell broadcast over a fourth-order tensor."""
    return x[:, None, None, None, None]


def t(x):
    """Scalar per cell broadcast over a second-order tensor."""
    return x[:, None, None]


def project(cb):
    """P : c_bar : P with P = I4 - 1/3 I (x) I (c_bar minor-symmetric)."""
    m = cb.shape[0]
    Id = eye(m)
    cI = np.einsum("mijkk->mij", cb) / 3.0
    Ic = np.einsum("miikl->mkl", cb) / 3.0
    IcI = np.einsum("miikk->m", cb) / 9.0
    return cb - dyad(Id, Ic) - dyad(cI, Id) + s(IcI) * dyad(Id, Id)


def uncoupled(J, sb, cb, p, pt):
    """sigma, c from the fictitious sigma_bar, c_bar and the volumetric p = U', pt = p + J U''."""
    m = J.shape[0]
    Id = eye(m)
    sd = dev(sb)
    I4 = sdyad(Id, Id)
    P = I4 - dyad(Id, Id) / 3.0
    c = project(cb) + s(2.0 / 3.0 * trace(sb)) * P - 2.0 / 3.0 * (dyad(sd, Id) + dyad(Id, sd))
    c = c + s(pt) * dyad(Id, Id) - s(2.0 * p) * I4
    return sd + t(p) * Id, c


def invariant_form(J, b, W1, W2, W11, W12, W22):
    """Fictitious sigma_bar, c_bar of W_iso(I1b, I2b) given its derivatives."""
    bb = t(J ** (-2.0 / 3.0)) * b
    bb2 = bb @ bb
    I1b = trace(bb)
    d = t(I1b) * bb - bb2
    sb = t(2.0 / J) * (t(W1) * bb + t(W2) * d)
    cb = s(W11) * dyad(bb, bb) + s(W12) * (dyad(bb, d) + dyad(d, bb)) + s(W22) * dyad(d, d)
    cb = cb + s(W2) * (dyad(bb, bb) - sdyad(bb, bb))
    return sb, s(4.0 / J) * cb


def log_volumetric(J, k0):
    """U = k0/2 (ln J)^2: U, p = U', pt = p + J U''."""
    lnJ = np.log(J)
    return 0.5 * k0 * lnJ**2, k0 * lnJ / J, k0 / J


# ------------------------------------------------------------------ materials
def isotropic_invariant(name, prm, J, b):
    m = J.shape[0]
    zero = np.zeros(m, dtype=REAL)
    I1b = J ** (-2.0 / 3.0) * trace(b)
    x = I1b - 3.0
    W2 = W12 = W22 = zero
    if name == "MooneyRivlin":
        I2b = 0.5 * (I1b**2 - J ** (-4.0 / 3.0) * trace(b @ b))
        W = prm["c1"] * x + prm["c2"] * (I2b - 3.0)
        W1, W11 = zero + prm["c1"], zero
        W2 = zero + prm["c2"]
    elif name == "VerondaWestmann":
        I2b = 0.5 * (I1b**2 - J ** (-4.0 / 3.0) * trace(b @ b))
        e = np.exp(prm["c2"] * x)
        W = prm["c1"] * (e - 1.0) - 0.5 * prm["c1"] * prm["c2"] * (I2b - 3.0)
        W1 = prm["c1"] * prm["c2"] * e
        W11 = prm["c1"] * prm["c2"] ** 2 * e
        W2 = zero - 0.5 * prm["c1"] * prm["c2"]
    elif name == "ArrudaBoyce":
        mu, N = prm["mu"], prm.get("N", REAL(8.0))
        W, W1, W11 = zero, zero, zero
        for i, ci in enumerate(AB_C, start=1):
            k = mu * ci * N ** (1 - i)
            W = W + k * (I1b**i - 3.0**i)
            W1 = W1 + k * i * I1b ** (i - 1)
            if i > 1:
                W11 = W11 + k * i * (i - 1) * I1b ** (i - 2)
    elif name == "Yeoh":
        c10, c20, c30 = prm["c10"], prm["c20"], prm["c30"]
        W = c10 * x + c20 * x**2 + c30 * x**3
        W1 = c10 + 2.0 * c20 * x + 3.0 * c30 * x**2
        W11 = 2.0 * c20 + 6.0 * c30 * x
    elif name == "Gent":
        mu, Jm = prm["mu"], prm["Jm"]
        r = 1.0 - x / Jm
        W = -0.5 * mu * Jm * np.log(r)
        W1 = 0.5 * mu / r
        W11 = 0.5 * mu / (Jm * r**2)
    elif name == "Demiray":
        a, bb = prm["a"], prm["b"]
        e = np.exp(bb * x)
        W = a / (2.0 * bb) * (e - 1.0)
        W1 = 0.5 * a * e
        W11 = 0.5 * a * bb * e
    else:
        raise ValueError(name)
    sb, cb = invariant_form(J, b, W1, W2, W11, W12, W22)
    U, p, pt = log_volumetric(J, prm["k0"])
    sigma, c = uncoupled(J, sb, cb, p, pt)
    return W + U, sigma, c


def neo_hookean(prm, J, b):
    mu, lam = prm["mu"], prm["lam"]
    m = J.shape[0]
    Id = eye(m)
    lnJ = np.log(J)
    W = 0.5 * mu * (trace(b) - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2
    sigma = t(mu / J) * (b - Id) + t(lam * lnJ / J) * Id
    c = s(lam / J) * dyad(Id, Id) + s(2.0 * (mu - lam * lnJ) / J) * sdyad(Id, Id)
    return W, sigma, c


def st_venant_kirchhoff(prm, J, b):
    mu, lam = prm["mu"], prm["lam"]
    # sigma = (1/J) F S F^T with S = lam tr E I + 2 mu E
    trE = 0.5 * (trace(b) - 3.0)
    trE2 = 0.25 * (trace(b @ b) - 2.0 * trace(b) + 3.0)
    W = 0.5 * lam * trE**2 + mu * trE2
    sigma = t(lam * trE / J) * b + t(mu / J) * (b @ b - b)
    c = s(lam / J) * dyad(b, b) + s(2.0 * mu / J) * sdyad(b, b)
    return W, sigma, c


def ogden(prm, J, b):
    mu, alpha, k0 = prm["mu"], prm["alpha"], prm["k0"]
    m = J.shape[0]
    lam2, n = np.linalg.eigh(b)  # principal stretches squared, spatial directions (columns)
    loglam = 0.5 * np.log(lam2)
    logbar = loglam - np.log(J)[:, None] / 3.0
    pa = np.exp(alpha * logbar)  # lambda_bar_a^alpha
    W = mu / alpha**2 * (pa.sum(axis=1) - 3.0)
    tb = mu / alpha * pa  # fictitious principal Kirchhoff stresses
    tau = tb - tb.sum(axis=1, keepdims=True) / 3.0  # deviatoric
    sa = tau / J[:, None]
    # d tau_a / d ln lambda_b
    dt = mu * (
        np.einsum("ma,ab->mab", pa, np.eye(3, dtype=REAL))
        - pa[:, :, None] / 3.0
        - pa[:, None, :] / 3.0
        + pa.sum(axis=1)[:, None, None] / 9.0
    )
    nn = np.einsum("mia,mja->maij", n, n)  # n_a (x) n_a
    sigma = np.einsum("ma,maij->mij", sa, nn)
    c = np.einsum("mab,maij,mbkl->mijkl", dt / J[:, None, None], nn, nn)
    c = c - 2.0 * np.einsum("ma,maij,makl->mijkl", sa, nn, nn)
    for a in range(3):
        for bi in range(3):
            if a == bi:
                continue
            # (sigma_a lam_b^2 - sigma_b lam_a^2) / (lam_a^2 - lam_b^2), written stably
            d = loglam[:, a] - loglam[:, bi]
            small = np.abs(d) < 1e-8
            quot = np.expm1(alpha * d) / np.where(small, 1.0, np.expm1(2.0 * d))
            ratio = np.where(small, alpha / 2.0, quot)  # equal-stretch limit
            diff = mu / alpha * np.exp(alpha * logbar[:, bi]) * ratio / lam2[:, bi] / J
            coef = -sa[:, a] + lam2[:, a] * diff
            na, nb = n[:, :, a], n[:, :, bi]
            ab = np.einsum("mi,mj->mij", na, nb)
            ba = np.einsum("mi,mj->mij", nb, na)
            c = c + s(coef) * (dyad(ab, ab) + dyad(ab, ba))
    U, p, pt = log_volumetric(J, k0)
    Id = eye(m)
    c = c + s(pt) * dyad(Id, Id) - s(2.0 * p) * sdyad(Id, Id)
    return W + U, sigma + t(p) * Id, c


def costa(prm, J, F, frame):
    a, k0 = prm["a"], prm["k0"]
    m = J.shape[0]
    Id = eye(m)
    B = np.array(
        [
            [prm["b_ff"], prm["b_fs"], prm["b_fn"]],
            [prm["b_fs"], prm["b_ss"], prm["b_sn"]],
            [prm["b_fn"], prm["b_sn"], prm["b_nn"]],
        ],
        dtype=REAL,
    )
    C = np.einsum("mki,mkj->mij", F, F)
    E = 0.5 * (C - Id)
    Ef = np.einsum("mai,mab,mbj->mij", frame, E, frame)  # R^T E R
    Q = np.einsum("ij,mij->m", B, Ef**2)
    A = J ** (-4.0 / 3.0)
    q = A * Q
    eq = np.exp(q)
    W = 0.5 * a * np.expm1(q)
    av = F @ frame  # pushed-forward frame a_i = F r_i (columns)
    BE = B[None] * Ef
    mm = np.einsum("mia,mab,mjb->mij", av, BE, av)  # F M F^T, M = R (B o Ef) R^T
    dq = t(A) * (mm - t(2.0 / 3.0 * Q) * Id)  # push-forward of dq/dC
    sigma = t(a * eq / J) * dq
    nsum = np.zeros((m, 3, 3, 3, 3), dtype=REAL)
    for i in range(3):
        for j in range(3):
            nij = 0.5 * (
                np.einsum("mk,ml->mkl", av[:, :, i], av[:, :, j])
                + np.einsum("mk,ml->mkl", av[:, :, j], av[:, :, i])
            )
            nsum = nsum + 0.5 * B[i, j] * dyad(nij, nij)
    d2q = nsum - 2.0 / 3.0 * (dyad(mm, Id) + dyad(Id, mm))
    d2q = d2q + s(4.0 / 9.0 * Q) * dyad(Id, Id) + s(2.0 / 3.0 * Q) * sdyad(Id, Id)
    c = s(2.0 * a * eq / J) * (dyad(dq, dq) + s(A) * d2q)
    lnJ = np.log(J)
    U = k0 * (J * lnJ - J + 1.0)
    p = k0 * lnJ
    pt = p + k0
    sigma = sigma + t(p) * Id
    c = c + s(pt) * dyad(Id, Id) - s(2.0 * p) * sdyad(Id, Id)
    return W + U, sigma, c


def material(name, prm, J, F, b, arrays):
    if name == "NeoHookean":
        return neo_hookean(prm, J, b)
    if name == "StVenantKirchhoff":
        return st_venant_kirchhoff(prm, J, b)
    if name == "Ogden":
        return ogden(prm, J, b)
    if name == "Costa":
        frame = arrays.get("frame")
        if frame is None:
            frame = np.broadcast_to(np.eye(3), (J.shape[0], 3, 3))
        frame = np.asarray(frame, dtype=REAL)
        if frame.ndim == 2:
            frame = np.broadcast_to(frame, (J.shape[0], 3, 3))
        return costa(prm, J, F, frame)
    return isotropic_invariant(name, prm, J, b)


# ------------------------------------------------------------------ element loop (vectorised)
def solve(case, arrays):
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n, m = X.shape[0], cells.shape[0]
    name = case["model"]["name"]
    prm = parameters(case["model"])

    Dm = np.stack([X[cells[:, k]] - X[cells[:, 0]] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([x[cells[:, k]] - x[cells[:, 0]] for k in (1, 2, 3)], axis=2)
    Dinv = np.linalg.inv(Dm)
    V0 = np.linalg.det(Dm) / 6.0
    G = np.concatenate([-Dinv.sum(axis=1, keepdims=True), Dinv], axis=1)  # (m, 4, 3)
    F = Ds @ Dinv
    J = np.linalg.det(F)
    Finv = np.linalg.inv(F)
    g = G @ Finv  # spatial gradients: g_a = F^-T G_a (rows)
    b = F @ np.swapaxes(F, 1, 2)
    v = J * V0

    W, sigma, c = material(name, prm, J, F, b, arrays)

    fe = -np.einsum("m,mij,maj->mai", v, sigma, g)  # (m, 4, 3)
    Kmat = np.einsum("maj,mijkl,mbl->maibk", g, c, g)
    geo = np.einsum("mai,mij,mbj->mab", g, sigma, g)
    Ke = v[:, None, None, None, None] * Kmat
    Ke = Ke + np.einsum("m,mab,ik->maibk", V0, geo, np.eye(3, dtype=REAL))

    dof = (3 * cells[:, :, None] + np.arange(3)[None, None, :]).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dof.reshape(-1), fe.reshape(-1))
    force = force.reshape(n, 3)
    rows = np.repeat(dof, 12, axis=1).reshape(-1)
    cols = np.tile(dof, (1, 12)).reshape(-1)
    vals = Ke.reshape(m, 144).reshape(-1)
    energy = None
    if WRITE_ENERGY:
        energy = np.sum(V0 * W)
    return force, (rows, cols, vals, 3 * n), energy


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
