#!/usr/bin/env python3
# MISTAKE: tr(C^2) in I2 = (I1^2 - tr C^2)/2 summed over the six Voigt components of C without the
# weight 2 of the shear pairs (C11^2 + C22^2 + C33^2 + C12^2 + C23^2 + C13^2): I2 and I2b too large
# wherever C has shear, in the energy, the stress and the tangent (right in the uniaxial state).
"""P1 tetrahedral hyperelastic engine, total Lagrangian in Voigt notation (Bathe / TLED style).

Precomputed per cell (vectorised over the m cells, no Python loop over cells): the rest
shape-function derivatives dh/dX (m, 4, 3) and rest volumes V0 (m,). At the current state:
the displacement gradient H = sum_a u_a (x) dh_a/dX from u = x - X, F = I + H, C = F^T F; the
second Piola-Kirchhoff stress S from the material as a Voigt 6-vector, order
(11, 22, 33, 12, 23, 13), tensor components; the material tangent D = 2 dS/dC = dS/dE as a
6 x 6 Voigt matrix against engineering shear strains (closed form for Neo-Hookean and St
Venant-Kirchhoff, spectral divided differences for Ogden, otherwise the complex step of S in
the six independent components of C); the nonlinear strain-displacement matrix
B = B_L0 + B_L1 (6 x 12, engineering shear rows); element force r = V0 B^T S, element matrix
K_e = V0 (B^T D B + K_geo), K_geo_ab = (dh_a . S dh_b) I3; assembly through the (m, 12) dof
map. Nodal force f = -r, stiffness K = d2Pi/dx2, energy Pi = sum V0 W.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one exported mjed-verify kit case).
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

LAYOUT = "coo"
WRITE_ENERGY = True
REAL = np.float64
CPLX = np.complex128
STEP = 1e-30

# Voigt order of this engine: (11, 22, 33, 12, 23, 13)
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
VI = np.array([p[0] for p in VOIGT])
VJ = np.array([p[1] for p in VOIGT])
# engineering strain: gamma_IJ = 2 E_IJ on the shear rows
ROWFAC = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0], dtype=REAL)
# a shear column of dS/dc moves C_IJ and C_JI together (gamma by one): half of a normal one
SHEARFAC = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5], dtype=REAL)
# Voigt weights of a full contraction A : B of symmetric tensors
VNORM = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0], dtype=REAL)
EYE = np.eye(3, dtype=REAL)
EYE_V = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0], dtype=REAL)
AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


# ------------------------------------------------------------ 3x3 algebra on stacks (m, 3, 3)


def det3(A):
    return (
        A[:, 0, 0] * (A[:, 1, 1] * A[:, 2, 2] - A[:, 1, 2] * A[:, 2, 1])
        - A[:, 0, 1] * (A[:, 1, 0] * A[:, 2, 2] - A[:, 1, 2] * A[:, 2, 0])
        + A[:, 0, 2] * (A[:, 1, 0] * A[:, 2, 1] - A[:, 1, 1] * A[:, 2, 0])
    )


def inv3(A):
    cof = np.empty_like(A)
    for i in range(3):
        for j in range(3):
            i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
            cof[:, i, j] = A[:, i1, j1] * A[:, i2, j2] - A[:, i1, j2] * A[:, i2, j1]
    return np.swapaxes(cof, 1, 2) / det3(A)[:, None, None]


def tensor_to_voigt(A):
    """Symmetric tensor (m, 3, 3) -> Voigt (m, 6), tensor components (stress-like)."""
    return A[:, VI, VJ]


def strain_to_voigt(A):
    """Symmetric strain (m, 3, 3) -> Voigt (m, 6) with engineering shears."""
    return A[:, VI, VJ] * ROWFAC


def voigt_to_tensor(v):
    """Voigt (m, 6), tensor components -> symmetric (m, 3, 3)."""
    A = np.empty(v.shape[:-1] + (3, 3), dtype=v.dtype)
    for k, (i, j) in enumerate(VOIGT):
        A[:, i, j] = v[:, k]
        A[:, j, i] = v[:, k]
    return A


def voigt_to_strain(v):
    """Voigt (m, 6) with engineering shears -> symmetric strain (m, 3, 3)."""
    return voigt_to_tensor(v / ROWFAC)


def invariants(Cv):
    C = voigt_to_tensor(Cv)
    J = np.sqrt(det3(C))
    Ci = inv3(C)
    I1 = Cv[:, 0] + Cv[:, 1] + Cv[:, 2]
    I2 = 0.5 * (I1**2 - np.sum(Cv * Cv, axis=1))
    return C, J, Ci, I1, I2


# ------------------------------------------------------------ materials: W(C), S(C), D


def iso_energy(name, p, I1b, I2b):
    t = I1b - 3.0
    if name == "MooneyRivlin":
        return p["c1"] * t + p["c2"] * (I2b - 3.0)
    if name == "VerondaWestmann":
        return p["c1"] * (np.exp(p["c2"] * t) - 1.0) - 0.5 * p["c1"] * p["c2"] * (I2b - 3.0)
    if name == "ArrudaBoyce":
        N = p["N"]
        return p["mu"] * sum(
            c * N ** (-i) * (I1b ** (i + 1) - 3.0 ** (i + 1)) for i, c in enumerate(AB_C)
        )
    if name == "Yeoh":
        return p["c10"] * t + p["c20"] * t**2 + p["c30"] * t**3
    if name == "Gent":
        return -0.5 * p["mu"] * p["Jm"] * np.log(1.0 - t / p["Jm"])
    if name == "Demiray":
        return 0.5 * p["a"] / p["b"] * (np.exp(p["b"] * t) - 1.0)
    raise ValueError(name)


def iso_slopes(name, p, I1b):
    """dW/dI1b and dW/dI2b."""
    t = I1b - 3.0
    zero = 0.0 * I1b
    if name == "MooneyRivlin":
        return p["c1"] + zero, p["c2"] + zero
    if name == "VerondaWestmann":
        return p["c1"] * p["c2"] * np.exp(p["c2"] * t), -0.5 * p["c1"] * p["c2"] + zero
    if name == "ArrudaBoyce":
        N = p["N"]
        W1 = p["mu"] * sum((i + 1) * c * N ** (-i) * I1b**i for i, c in enumerate(AB_C))
        return W1, zero
    if name == "Yeoh":
        return p["c10"] + 2.0 * p["c20"] * t + 3.0 * p["c30"] * t**2, zero
    if name == "Gent":
        return 0.5 * p["mu"] / (1.0 - t / p["Jm"]), zero
    if name == "Demiray":
        return 0.5 * p["a"] * np.exp(p["b"] * t), zero
    raise ValueError(name)


def strain_rotation(R):
    """Ef_v = T E_v for engineering Voigt strains, Ef = R^T E R; T per cell (m, 6, 6)."""
    p, q = VI[:, None], VJ[:, None]
    k, l = VI[None, :], VJ[None, :]
    T = 0.5 * (R[:, k, p] * R[:, l, q] + R[:, l, p] * R[:, k, q])
    return T * ROWFAC[:, None]


def costa_parts(p, Cv, T):
    C, J, Ci, I1, I2 = invariants(Cv)
    Ev = strain_to_voigt(0.5 * (C - EYE))
    Efv = np.einsum("mij,mj->mi", T, Ev)
    # B in this engine's Voigt order: ff, ss, nn, fs, sn, fn
    Bv = np.array([p["b_ff"], p["b_ss"], p["b_nn"], p["b_fs"], p["b_sn"], p["b_fn"]])
    # Q = sum_ij B_ij Ef_ij^2 = sum B_k QW_k Ef_k^2 (a shear pair: 2 B (gamma/2)^2)
    QW = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])
    Q = np.sum(Bv * QW * Efv**2, axis=1)
    dQ_dEf = 2.0 * QW * Bv * Efv
    dQ_dE = np.einsum("mji,mj->mi", T, dQ_dEf)
    return C, J, Ci, Q, dQ_dE


def energy_density(name, p, Cv, T):
    if name == "Ogden":
        C = voigt_to_tensor(Cv)
        lam = np.linalg.eigvalsh(C)
        J = np.sqrt(np.prod(lam, axis=1))
        a = p["alpha"]
        Wi = p["mu"] / a**2 * (J ** (-a / 3.0) * np.sum(lam ** (0.5 * a), axis=1) - 3.0)
        return Wi + 0.5 * p["k0"] * np.log(J) ** 2
    if name == "Costa":
        C, J, Ci, Q, dQ_dE = costa_parts(p, Cv, T)
        g = J ** (-4.0 / 3.0) * Q
        return 0.5 * p["a"] * (np.exp(g) - 1.0) + p["k0"] * (J * np.log(J) - J + 1.0)
    C, J, Ci, I1, I2 = invariants(Cv)
    if name == "StVenantKirchhoff":
        Ev = strain_to_voigt(0.5 * (C - EYE))
        trE = Ev[:, 0] + Ev[:, 1] + Ev[:, 2]
        EE = Ev[:, 0] ** 2 + Ev[:, 1] ** 2 + Ev[:, 2] ** 2 + 0.5 * np.sum(Ev[:, 3:] ** 2, axis=1)
        return 0.5 * p["lam"] * trE**2 + p["mu"] * EE
    lnJ = np.log(J)
    if name == "NeoHookean":
        return 0.5 * p["mu"] * (I1 - 3.0) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ**2
    I1b = J ** (-2.0 / 3.0) * I1
    I2b = J ** (-4.0 / 3.0) * I2
    return iso_energy(name, p, I1b, I2b) + 0.5 * p["k0"] * lnJ**2


def ogden_spectral(p, Cv):
    C = voigt_to_tensor(Cv)
    lam, Qv = np.linalg.eigh(C)
    a = p["alpha"]
    e = 0.5 * a - 1.0
    f = lam**e
    G = np.einsum("mia,ma,mja->mij", Qv, f, Qv)
    T = np.sum(lam ** (0.5 * a), axis=1)
    J = np.sqrt(np.prod(lam, axis=1))
    return C, lam, Qv, f, e, G, T, J


def stress(name, p, Cv, T):
    """Second Piola-Kirchhoff stress, Voigt (m, 6), tensor components."""
    if name == "Ogden":
        C, lam, Qv, f, e, G, Tsum, J = ogden_spectral(p, Cv)
        Ci = inv3(C)
        a, g = p["alpha"], J ** (-p["alpha"] / 3.0)
        S = p["mu"] / a * g[:, None, None] * (G - (Tsum / 3.0)[:, None, None] * Ci)
        S = S + (p["k0"] * np.log(J))[:, None, None] * Ci
        return tensor_to_voigt(S)
    if name == "Costa":
        C, J, Ci, Q, dQ_dE = costa_parts(p, Cv, T)
        dQ_dC = 0.5 * voigt_to_tensor(dQ_dE)
        Jm43 = J ** (-4.0 / 3.0)
        eg = np.exp(Jm43 * Q)
        S_iso = (p["a"] * eg * Jm43)[:, None, None] * (dQ_dC - (2.0 / 3.0 * Q)[:, None, None] * Ci)
        S = S_iso + (p["k0"] * J * np.log(J))[:, None, None] * Ci
        return tensor_to_voigt(S)
    C, J, Ci, I1, I2 = invariants(Cv)
    lnJ = np.log(J)
    if name == "StVenantKirchhoff":
        Ev = strain_to_voigt(0.5 * (C - EYE))
        trE = Ev[:, 0] + Ev[:, 1] + Ev[:, 2]
        return p["lam"] * trE[:, None] * EYE_V + 2.0 * p["mu"] * Ev / ROWFAC
    if name == "NeoHookean":
        S = p["mu"] * (EYE - Ci) + (p["lam"] * lnJ)[:, None, None] * Ci
        return tensor_to_voigt(S)
    Jm23 = J ** (-2.0 / 3.0)
    I1b = Jm23 * I1
    W1, W2 = iso_slopes(name, p, I1b)
    dI1b = Jm23[:, None, None] * (EYE - (I1 / 3.0)[:, None, None] * Ci)
    dI2b = (Jm23**2)[:, None, None] * (
        I1[:, None, None] * EYE - C - (2.0 / 3.0 * I2)[:, None, None] * Ci
    )
    S = 2.0 * (W1[:, None, None] * dI1b + W2[:, None, None] * dI2b)
    S = S + (p["k0"] * lnJ)[:, None, None] * Ci
    return tensor_to_voigt(S)


def tangent_complex_step(name, p, Cv, T):
    """D = 2 dS/dC, (m, 6, 6), from the complex step of S in the six components of C."""
    m = len(Cv)
    dS = np.empty((m, 6, 6), dtype=REAL)
    for k in range(6):
        h = STEP * np.maximum(np.abs(Cv[:, k]), 1.0)
        Cp = Cv.astype(CPLX)
        Cp[:, k] += 1j * h
        dS[:, :, k] = stress(name, p, Cp, T).imag / h[:, None]
    return 2.0 * dS * SHEARFAC[None, :]


def tangent_ogden(p, Cv):
    """D = 2 dS/dC for Ogden: spectral divided differences of G = C^(alpha/2 - 1)."""
    C, lam, Qv, f, e, G, Tsum, J = ogden_spectral(p, Cv)
    Ci = inv3(C)
    a = p["alpha"]
    g = J ** (-a / 3.0)
    fprime = e * lam ** (e - 1.0)
    dl = lam[:, :, None] - lam[:, None, :]
    close = np.abs(dl) <= 1e-9 * np.max(np.abs(lam), axis=1)[:, None, None]
    safe = np.where(close, 1.0, dl)
    mean_fp = 0.5 * (fprime[:, :, None] + fprime[:, None, :])
    # f(la) - f(lb) = lb^e expm1(e log1p((la - lb)/lb)): no cancellation for close eigenvalues
    lb = lam[:, None, :]
    Gdd = np.where(close, mean_fp, lb**e * np.expm1(e * np.log1p(dl / lb)) / safe)
    # the six unit directions of C (both entries of a shear pair)
    E6 = np.zeros((6, 3, 3), dtype=REAL)
    for k, (i, j) in enumerate(VOIGT):
        E6[k, i, j] = 1.0
        E6[k, j, i] = 1.0
    CiE = np.einsum("mij,kij->mk", Ci, E6)
    GE = np.einsum("mij,kij->mk", G, E6)
    CiECi = np.einsum("mij,kjl,mln->mkin", Ci, E6, Ci)
    QEQ = np.einsum("mia,kij,mjb->mkab", Qv, E6, Qv)
    dG = np.einsum("mia,mkab,mjb->mkij", Qv, Gdd[:, None] * QEQ, Qv)
    c = p["mu"] / a
    Tm = (Tsum / 3.0)[:, None, None, None]
    dS = (
        c * (-a / 6.0) * (g[:, None] * CiE)[:, :, None, None] * (G[:, None] - Tm * Ci[:, None])
        + c
        * g[:, None, None, None]
        * (dG - (a / 6.0) * GE[:, :, None, None] * Ci[:, None] + Tm * CiECi)
        + p["k0"]
        * (0.5 * CiE[:, :, None, None] * Ci[:, None] - np.log(J)[:, None, None, None] * CiECi)
    )
    dSv = dS[:, :, VI, VJ]  # (m, direction k, Voigt i)
    return 2.0 * np.swapaxes(dSv, 1, 2) * SHEARFAC[None, :]


def tangent(name, p, Cv, T):
    if name == "StVenantKirchhoff":
        D = p["lam"] * np.outer(EYE_V, EYE_V) + 2.0 * p["mu"] * np.diag(SHEARFAC)
        return np.broadcast_to(D, (len(Cv), 6, 6))
    if name == "NeoHookean":
        C, J, Ci, I1, I2 = invariants(Cv)
        c2 = p["mu"] - p["lam"] * np.log(J)
        a, b = VI[:, None], VJ[:, None]
        k, l = VI[None, :], VJ[None, :]
        CiCi = Ci[:, a, k] * Ci[:, b, l] + Ci[:, a, l] * Ci[:, b, k]
        Cv_i = Ci[:, VI, VJ]
        return p["lam"] * Cv_i[:, :, None] * Cv_i[:, None, :] + c2[:, None, None] * CiCi
    if name == "Ogden":
        return tangent_ogden(p, Cv)
    return tangent_complex_step(name, p, Cv, T)


# ------------------------------------------------------------ strain-displacement matrices


def b_matrices(H, dh):
    """B_L0 and B_L1 (m, 6, 12): rows in Voigt order, engineering shear rows."""
    m = len(dh)
    B0 = np.zeros((m, 6, 4, 3), dtype=H.dtype)
    B1 = np.zeros((m, 6, 4, 3), dtype=H.dtype)
    for r, (I, J) in enumerate(VOIGT):
        # row IJ, column (a, k): F_kI dh_aJ + F_kJ dh_aI (once if I == J), F = I + H
        B0[:, r] = EYE[None, None, :, I] * dh[:, :, J, None]
        B1[:, r] = H[:, None, :, I] * dh[:, :, J, None]
        if I != J:
            B0[:, r] += EYE[None, None, :, J] * dh[:, :, I, None]
            B1[:, r] += H[:, None, :, J] * dh[:, :, I, None]
    return B0.reshape(m, 6, 12), B1.reshape(m, 6, 12)


# ------------------------------------------------------------ the engine


def precompute(X, cells):
    """Rest shape-function derivatives dh/dX (m, 4, 3) and rest volumes V0 (m,)."""
    Xe = X[cells]
    Dm = np.stack([Xe[:, 1] - Xe[:, 0], Xe[:, 2] - Xe[:, 0], Xe[:, 3] - Xe[:, 0]], axis=2)
    V0 = det3(Dm) / 6.0
    Dinv = inv3(Dm)  # its rows are dh_1, dh_2, dh_3
    dh = np.empty((len(cells), 4, 3), dtype=X.dtype)
    dh[:, 1:] = Dinv
    dh[:, 0] = -Dinv.sum(axis=1)
    return dh, V0


def solve(case, arrays):
    model = case["model"]
    name = model["name"]
    p = dict(model["parameters"])
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n, m = len(X), len(cells)
    T = None
    if name == "Costa":
        R = arrays["frame"].reshape(m, 3, 3).astype(REAL)
        T = strain_rotation(R)

    dh, V0 = precompute(X, cells)
    u = x[cells] - X[cells]
    H = np.einsum("mak,maJ->mkJ", u, dh)
    F = EYE + H
    C = np.einsum("mkI,mkJ->mIJ", F, F)
    Cv = tensor_to_voigt(C)

    Sv = stress(name, p, Cv, T).real.astype(REAL)
    D = tangent(name, p, Cv, T)
    B0, B1 = b_matrices(H, dh)
    B = B0 + B1

    r = V0[:, None] * np.einsum("mij,mi->mj", B, Sv)
    Kmat = np.einsum("mij,mik,mkl->mjl", B, D, B)
    S = voigt_to_tensor(Sv)
    G = np.einsum("maI,mIJ,mbJ->mab", dh, S, dh)
    Kgeo = np.einsum("mab,kl->makbl", G, EYE).reshape(m, 12, 12)
    Ke = V0[:, None, None] * (Kmat + Kgeo)

    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, -r)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.ravel()

    energy = None
    if WRITE_ENERGY:
        W = energy_density(name, p, Cv, T).real
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
