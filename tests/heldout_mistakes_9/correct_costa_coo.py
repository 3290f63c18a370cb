#!/usr/bin/env python3
# CONTROL (no mistake): float64, per-cell fibre frames, Costa through S (fibre-frame Green strain)
# and sigma = F S F^T / J, complex-step element stiffness, element COO stiffness.
"""One kit case of mjed-verify: python ENGINE INPUT_DIR OUTPUT_DIR.

Research-code style hyperelastic P1 tetrahedra, vectorised over the cells: F from the deformed
and rest edge matrices, b = F F^T, the Cauchy stress sigma(b, J) in closed form for each
material (isochoric/volumetric split as the law defines it; Ogden through the matrix power
b^(alpha/2) by a Denman-Beavers square root; St Venant-Kirchhoff and Costa through S and
sigma = F S F^T / J), element forces over the deformed cell f_a = -v sigma grad_x N_a, and the
element stiffness by complex-step differentiation of that force routine,
K_e[:, j] = -Im f(x + i h e_j) / h. Energy sum V0 W.
"""

import json
import os
import sys

import numpy as np
import scipy.sparse as sp

LAYOUT = "coo"
WRITE_ENERGY = True
REAL = np.float64
CPLX = np.complex128
SUFFIX = "f64"
H = 1e-30
AB_C = (0.5, 0.05, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)
DB_ITER = 30


def read_case(folder):
    with open(os.path.join(folder, "case.json")) as fh:
        case = json.load(fh)
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(os.path.join(folder, spec["file"]), dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


def tr(A):
    return A[..., 0, 0] + A[..., 1, 1] + A[..., 2, 2]


def T(A):
    return np.swapaxes(A, -1, -2)


def sc(s):
    return s[..., None, None]


def eye_like(A):
    return np.broadcast_to(np.eye(3, dtype=REAL), A.shape)


def det3(A):
    return (
        A[..., 0, 0] * (A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1])
        - A[..., 0, 1] * (A[..., 1, 0] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 0])
        + A[..., 0, 2] * (A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0])
    )


def cof3(A):
    """Cofactor matrix det(A) A^-T, columns a1 x a2, a2 x a0, a0 x a1 (complex-safe)."""
    a0, a1, a2 = A[..., :, 0], A[..., :, 1], A[..., :, 2]
    return np.stack([np.cross(a1, a2), np.cross(a2, a0), np.cross(a0, a1)], axis=-1)


def inv3(A):
    return T(cof3(A)) / sc(det3(A))


def dev(A):
    return A - sc(tr(A) / 3.0) * eye_like(A)


def sqrtm(A):
    """Denman-Beavers iteration: only products and inverses, so it carries the complex step."""
    Y, Z = A, eye_like(A)
    for _ in range(DB_ITER):
        Y, Z = 0.5 * (Y + inv3(Z)), 0.5 * (Z + inv3(Y))
    return Y


def matpow(A, p):
    k, r = divmod(int(round(2.0 * p)), 2)
    assert abs(2.0 * p - round(2.0 * p)) < 1e-12, "alpha must be an integer"
    M = sqrtm(A) if r else eye_like(A) + 0.0 * A
    base = A if k >= 0 else inv3(A)
    for _ in range(abs(k)):
        M = M @ base
    return M


def iso_tau(b, J, psi):
    """Kirchhoff stress of Psi(I1b, I2b): 2 dev[(psi1 + I1b psi2) bb - psi2 bb^2]."""
    bb = sc(J ** (-2.0 / 3.0)) * b
    I1b = tr(bb)
    I2b = 0.5 * (I1b**2 - tr(bb @ bb))
    psi1, psi2 = psi(I1b, I2b)
    A = sc(psi1) * bb + sc(psi2) * (sc(I1b) * bb - bb @ bb)
    return 2.0 * dev(A)


def vol_tau(J, k0):
    """J U'(J) I for U = k0/2 (ln J)^2."""
    return sc(k0 * np.log(J)) * np.eye(3, dtype=REAL)


def cauchy(F, b, J, name, p, R):
    if name == "NeoHookean":
        tau = p["mu"] * (b - eye_like(b)) + sc(p["lam"] * np.log(J)) * eye_like(b)
    elif name == "StVenantKirchhoff":
        C = T(F) @ F
        E = 0.5 * (C - eye_like(C))
        S = sc(p["lam"] * tr(E)) * eye_like(C) + 2.0 * p["mu"] * E
        tau = F @ S @ T(F)
    elif name == "Ogden":
        mu, al = p["mu"], p["alpha"]
        M = matpow(b, 0.5 * al)
        tau = sc(mu / al * J ** (-al / 3.0)) * dev(M) + vol_tau(J, p["k0"])
    elif name == "Costa":
        B = costa_B(p)
        C = T(F) @ F
        E = 0.5 * (C - eye_like(C))
        Ef = T(R) @ E @ R
        Q = np.sum(B * Ef * Ef, axis=(-1, -2))
        Hm = R @ (B * Ef) @ T(R)
        Ci = inv3(C)
        Jq = J ** (-4.0 / 3.0)
        e = np.exp(Jq * Q)
        S = sc(p["a"] * e * Jq) * (Hm - sc(2.0 / 3.0 * Q) * Ci) + sc(p["k0"] * J * np.log(J)) * Ci
        tau = F @ S @ T(F)
    else:
        tau = iso_tau(b, J, psi_of(name, p)) + vol_tau(J, p["k0"])
    return tau / sc(J)


def psi_of(name, p):
    """(dPsi/dI1b, dPsi/dI2b) of the isochoric part."""
    if name == "MooneyRivlin":
        return lambda I1b, I2b: (p["c1"] + 0.0 * I1b, p["c2"] + 0.0 * I1b)
    if name == "Yeoh":
        c10, c20, c30 = p["c10"], p["c20"], p["c30"]

        def yeoh(I1b, I2b):
            x = I1b - 3.0
            return c10 + 2.0 * c20 * x + 3.0 * c30 * x**2, 0.0 * I1b

        return yeoh
    if name == "ArrudaBoyce":
        mu, N = p["mu"], p["N"]

        def ab(I1b, I2b):
            s = 0.0 * I1b
            for i in range(1, 6):
                s = s + i * mu * AB_C[i - 1] * N ** (1 - i) * I1b ** (i - 1)
            return s, 0.0 * I1b

        return ab
    if name == "Gent":
        mu, Jm = p["mu"], p["Jm"]
        return lambda I1b, I2b: (0.5 * mu / (1.0 - (I1b - 3.0) / Jm), 0.0 * I1b)
    if name == "VerondaWestmann":
        c1, c2 = p["c1"], p["c2"]

        def vw(I1b, I2b):
            e = np.exp(c2 * (I1b - 3.0))
            return c1 * c2 * e, -0.5 * c1 * c2 + 0.0 * I1b

        return vw
    if name == "Demiray":
        a, bb = p["a"], p["b"]

        def dem(I1b, I2b):
            e = np.exp(bb * (I1b - 3.0))
            return 0.5 * a * e, 0.0 * I1b

        return dem
    raise SystemExit(f"unknown material {name}")


def costa_B(p):
    return np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ],
        dtype=REAL,
    )


def energy_density(F, name, p, R):
    J = det3(F)
    lnJ = np.log(J)
    C = T(F) @ F
    I1 = tr(C)
    I2 = 0.5 * (I1**2 - tr(C @ C))
    I1b, I2b = J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2
    if name == "NeoHookean":
        return 0.5 * p["mu"] * (I1 - 3.0) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ**2
    if name == "StVenantKirchhoff":
        E = 0.5 * (C - eye_like(C))
        return 0.5 * p["lam"] * tr(E) ** 2 + p["mu"] * tr(E @ E)
    if name == "Costa":
        E = 0.5 * (C - eye_like(C))
        Ef = T(R) @ E @ R
        Q = np.sum(costa_B(p) * Ef * Ef, axis=(-1, -2))
        return 0.5 * p["a"] * (np.exp(J ** (-4.0 / 3.0) * Q) - 1.0) + p["k0"] * (J * lnJ - J + 1.0)
    U = 0.5 * p["k0"] * lnJ**2
    if name == "Ogden":
        mu, al = p["mu"], p["alpha"]
        lam = np.linalg.eigvalsh(C)
        return mu / al**2 * (J ** (-al / 3.0) * np.sum(lam ** (0.5 * al), axis=-1) - 3.0) + U
    x = I1b - 3.0
    if name == "MooneyRivlin":
        return p["c1"] * x + p["c2"] * (I2b - 3.0) + U
    if name == "Yeoh":
        return p["c10"] * x + p["c20"] * x**2 + p["c30"] * x**3 + U
    if name == "ArrudaBoyce":
        s = 0.0 * x
        for i in range(1, 6):
            s = s + AB_C[i - 1] * p["N"] ** (1 - i) * (I1b**i - 3.0**i)
        return p["mu"] * s + U
    if name == "Gent":
        return -0.5 * p["mu"] * p["Jm"] * np.log(1.0 - x / p["Jm"]) + U
    if name == "VerondaWestmann":
        c1, c2 = p["c1"], p["c2"]
        return c1 * (np.exp(c2 * x) - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0) + U
    if name == "Demiray":
        return p["a"] / (2.0 * p["b"]) * (np.exp(p["b"] * x) - 1.0) + U
    raise SystemExit(f"unknown material {name}")


def element_forces(xe, Dinv, V0, name, p, R):
    """Forces on the 4 nodes of every cell, (m, 12) node-major: f_a = -v sigma grad_x N_a."""
    Ds = T(xe[:, 1:, :] - xe[:, :1, :])
    F = Ds @ Dinv
    J = det3(F)
    b = F @ T(F)
    sigma = cauchy(F, b, J, name, p, R)
    Gref = np.concatenate([-np.sum(T(Dinv), axis=-1, keepdims=True), T(Dinv)], axis=-1)
    Gx = T(inv3(F)) @ Gref
    v = J * V0
    f = -sc(v) * (sigma @ Gx)
    return T(f).reshape(len(xe), 12)


def element_stiffness(xe, Dinv, V0, name, p, R):
    """K_e[:, j] = -Im f(x + i h e_j) / h (K = -df/dx), every cell at once for each j."""
    Ke = np.empty((len(xe), 12, 12), dtype=REAL)
    for j in range(12):
        xc = xe.astype(CPLX)
        xc[:, j // 3, j % 3] += 1j * H
        Ke[:, :, j] = -np.imag(element_forces(xc, Dinv, V0, name, p, R)) / H
    return Ke


def main(inp, out):
    case, arrays = read_case(inp)
    model = case["model"]
    name = model["name"]
    p = {k: float(v) for k, v in model["parameters"].items()}
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    R = arrays["frame"].astype(REAL) if "frame" in arrays else None
    if R is not None and R.ndim == 2:
        R = np.broadcast_to(R, (len(cells), 3, 3))
    n, m = len(X), len(cells)
    Dm = T(X[cells[:, 1:]] - X[cells[:, :1]])
    Dinv = inv3(Dm)
    V0 = det3(Dm) / 6.0
    xe = x[cells]
    fe = element_forces(xe, Dinv, V0, name, p, R)
    Ke = element_stiffness(xe, Dinv, V0, name, p, R)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, fe)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.reshape(m, 144).ravel()
    os.makedirs(out, exist_ok=True)

    def write(stem, arr, real=True):
        dtype = ("<f4" if SUFFIX == "f32" else "<f8") if real else "<i8"
        ext = SUFFIX if real else "i64"
        np.ascontiguousarray(arr).astype(dtype).tofile(os.path.join(out, f"{stem}.{ext}"))

    write("force", force)
    N = 3 * n
    if LAYOUT == "dense":
        K = np.zeros((N, N), dtype=REAL)
        np.add.at(K, (rows, cols), vals)
        write("stiffness", K)
    elif LAYOUT == "coo":
        write("stiffness_rows", rows, False)
        write("stiffness_cols", cols, False)
        write("stiffness_values", vals)
    else:
        K = sp.coo_matrix((vals, (rows, cols)), shape=(N, N)).tocsr()
        K.sum_duplicates()
        K.sort_indices()
        write("stiffness_indptr", K.indptr, False)
        write("stiffness_indices", K.indices, False)
        write("stiffness_values", K.data)
    if WRITE_ENERGY:
        F = T(xe[:, 1:, :] - xe[:, :1, :]) @ Dinv
        W = energy_density(F, name, p, R)
        write("energy", np.array([np.sum(V0 * W)]))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
