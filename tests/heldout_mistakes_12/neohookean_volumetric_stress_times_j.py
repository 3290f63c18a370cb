#!/usr/bin/env python3
# MISTAKE: Neo-Hookean stress written mu F + (lam J ln J - mu) F^-T: d(lam/2 (ln J)^2)/dF taken as
# lam ln J dJ/dF = lam ln J J F^-T (the 1/J of d ln J/dJ lost) where lam ln J F^-T belongs; energy
# and the closed-form tangent right, force wrong.
"""P1 tetrahedral hyperelastic engine in the FElupe / scikit-fem style.

Arrays keep their tensor components first and the quadrature point and cell axes last:
X and x per cell are (4, 3, q, m), the gradients dhdX (4, 3, q, m), F and P (3, 3, q, m), the
first elasticity tensor A = dP/dF (3, 3, 3, 3, q, m). One quadrature point (q = 1) whose weight
is the reference tetrahedron's volume 1/6 times det(dX/dr). Element force r_a = int P . dhdX_a,
element matrix K_ab = int dhdX_a . A . dhdX_b, assembled through the (cells x 12) dof map.

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


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


# ----------------------------------------------------------------- trailing-axis algebra


def det3(A):
    return (
        A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
        - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
        + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0])
    )


def inv3(A):
    cof = np.empty_like(A)
    for i in range(3):
        for j in range(3):
            i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
            cof[i, j] = A[i1, j1] * A[i2, j2] - A[i1, j2] * A[i2, j1]
    return np.swapaxes(cof, 0, 1) / det3(A)


def dot(A, B):
    return np.einsum("ik...,kj...->ij...", A, B)


def trace(A):
    return np.einsum("ii...->...", A)


def eye_like(A):
    eye = np.zeros_like(A)
    for i in range(3):
        eye[i, i] = 1.0
    return eye


def sqrtm(C, iterations=30):
    """Denman-Beavers square root, vectorised over the trailing axes (complex-safe)."""
    Y, Z = C, eye_like(C)
    for _ in range(iterations):
        Y, Z = 0.5 * (Y + inv3(Z)), 0.5 * (Z + inv3(Y))
    return Y


def kinematics(F):
    J = det3(F)
    FiT = np.swapaxes(inv3(F), 0, 1)
    C = np.einsum("kIqm,kJqm->IJqm", F, F)
    I1 = trace(C)
    I2 = 0.5 * (I1**2 - np.einsum("IJqm,JIqm->qm", C, C))
    return J, FiT, C, I1, I2


def isochoric(F):
    J, FiT, C, I1, I2 = kinematics(F)
    I1b = J ** (-2.0 / 3.0) * I1
    I2b = J ** (-4.0 / 3.0) * I2
    dI1b = J ** (-2.0 / 3.0) * (2.0 * F - 2.0 / 3.0 * I1 * FiT)
    FC = np.einsum("iKqm,KJqm->iJqm", F, C)
    dI2b = J ** (-4.0 / 3.0) * (2.0 * (I1 * F - FC) - 4.0 / 3.0 * I2 * FiT)
    return J, FiT, I1b, I2b, dI1b, dI2b


# ----------------------------------------------------------------- materials: W(F), P(F)

AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def iso_energy(name, p, I1b, I2b):
    t = I1b - 3.0
    if name == "MooneyRivlin":
        return p["c1"] * t + p["c2"] * (I2b - 3.0)
    if name == "VerondaWestmann":
        return p["c1"] * (np.exp(p["c2"] * t) - 1.0) - 0.5 * p["c1"] * p["c2"] * (I2b - 3.0)
    if name == "ArrudaBoyce":
        return p["mu"] * sum(
            c * p["N"] ** (-i) * (I1b ** (i + 1) - 3.0 ** (i + 1)) for i, c in enumerate(AB_C)
        )
    if name == "Yeoh":
        return p["c10"] * t + p["c20"] * t**2 + p["c30"] * t**3
    if name == "Gent":
        return -0.5 * p["mu"] * p["Jm"] * np.log(1.0 - t / p["Jm"])
    if name == "Demiray":
        return p["a"] / (2.0 * p["b"]) * (np.exp(p["b"] * t) - 1.0)
    raise ValueError(name)


def iso_slopes(name, p, I1b, I2b):
    """dW/dI1b and dW/dI2b."""
    t = I1b - 3.0
    zero = 0.0 * I1b
    if name == "MooneyRivlin":
        return p["c1"] + zero, p["c2"] + zero
    if name == "VerondaWestmann":
        return p["c1"] * p["c2"] * np.exp(p["c2"] * t), -0.5 * p["c1"] * p["c2"] + zero
    if name == "ArrudaBoyce":
        w1 = p["mu"] * sum((i + 1) * c * p["N"] ** (-i) * I1b**i for i, c in enumerate(AB_C))
        return w1, zero
    if name == "Yeoh":
        return p["c10"] + 2.0 * p["c20"] * t + 3.0 * p["c30"] * t**2, zero
    if name == "Gent":
        return 0.5 * p["mu"] / (1.0 - t / p["Jm"]), zero
    if name == "Demiray":
        return 0.5 * p["a"] * np.exp(p["b"] * t), zero
    raise ValueError(name)


def costa_strain(F, R, J):
    C = np.einsum("kIqm,kJqm->IJqm", F, F)
    E = 0.5 * (C - eye_like(C))
    return np.einsum("Iim,IJqm,Jjm->ijqm", R, E, R)


def costa_B(p):
    return np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ]
    )


def energy_density(name, p, F, R):
    if name == "StVenantKirchhoff":
        C = np.einsum("kIqm,kJqm->IJqm", F, F)
        E = 0.5 * (C - eye_like(C))
        trE = trace(E)
        return 0.5 * p["lam"] * trE**2 + p["mu"] * np.einsum("IJqm,IJqm->qm", E, E)
    if name == "NeoHookean":
        J, _, _, I1, _ = kinematics(F)
        lnJ = np.log(J)
        return 0.5 * p["mu"] * (I1 - 3.0) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ**2
    if name == "Costa":
        J = det3(F)
        Ef = costa_strain(F, R, J)
        Q = np.einsum("ij,ijqm,ijqm->qm", costa_B(p), Ef, Ef)
        return 0.5 * p["a"] * (np.exp(J ** (-4.0 / 3.0) * Q) - 1.0) + p["k0"] * (
            J * np.log(J) - J + 1.0
        )
    if name == "Ogden":
        J, _, C, _, _ = kinematics(F)
        alpha = p["alpha"]
        T = trace(dot(C, ogden_power(C, alpha)))
        return p["mu"] / alpha**2 * (J ** (-alpha / 3.0) * T - 3.0) + 0.5 * p["k0"] * np.log(J) ** 2
    J, _, I1b, I2b, _, _ = isochoric(F)
    return iso_energy(name, p, I1b, I2b) + 0.5 * p["k0"] * np.log(J) ** 2


def ogden_power(C, alpha):
    """C^(alpha/2 - 1) for an integer alpha, through the square root of C."""
    k = int(round(alpha)) - 2
    if abs(alpha - round(alpha)) > 1e-12:
        raise ValueError("this engine's Ogden needs an integer alpha")
    root = sqrtm(C) if k >= 0 else inv3(sqrtm(C))
    out = eye_like(C)
    for _ in range(abs(k)):
        out = dot(out, root)
    return out


def stress(name, p, F, R):
    """First Piola-Kirchhoff stress P (3, 3, q, m)."""
    if name == "StVenantKirchhoff":
        C = np.einsum("kIqm,kJqm->IJqm", F, F)
        I = eye_like(C)
        E = 0.5 * (C - I)
        S = p["lam"] * trace(E) * I + 2.0 * p["mu"] * E
        return dot(F, S)
    if name == "NeoHookean":
        J, FiT, _, _, _ = kinematics(F)
        return p["mu"] * F + (p["lam"] * np.log(J) * J - p["mu"]) * FiT
    if name == "Costa":
        J, FiT, _, _, _ = kinematics(F)
        Ef = costa_strain(F, R, J)
        B = costa_B(p)
        Q = np.einsum("ij,ijqm,ijqm->qm", B, Ef, Ef)
        g = J ** (-4.0 / 3.0)
        dQdE = np.einsum("iIm,IJqm,jJm->ijqm", R, 2.0 * B[:, :, None, None] * Ef, R)
        fibre = 0.5 * p["a"] * np.exp(g * Q) * (g * dot(F, dQdE) - 4.0 / 3.0 * g * Q * FiT)
        return fibre + p["k0"] * np.log(J) * J * FiT
    if name == "Ogden":
        J, FiT, C, _, _ = kinematics(F)
        alpha = p["alpha"]
        M = ogden_power(C, alpha)
        T = trace(dot(C, M))
        g = J ** (-alpha / 3.0)
        iso = p["mu"] / alpha**2 * (g * alpha * dot(F, M) - alpha / 3.0 * g * T * FiT)
        return iso + p["k0"] * np.log(J) * FiT
    J, FiT, I1b, I2b, dI1b, dI2b = isochoric(F)
    w1, w2 = iso_slopes(name, p, I1b, I2b)
    return w1 * dI1b + w2 * dI2b + p["k0"] * np.log(J) * FiT


def closed_form_tangent(name, p, F):
    """A = dP/dF written out for St Venant-Kirchhoff and Neo-Hookean."""
    I = np.eye(3, dtype=F.dtype)
    if name == "StVenantKirchhoff":
        C = np.einsum("kIqm,kJqm->IJqm", F, F)
        E = 0.5 * (C - eye_like(C))
        S = p["lam"] * trace(E) * eye_like(C) + 2.0 * p["mu"] * E
        b = np.einsum("iIqm,kIqm->ikqm", F, F)
        geo = np.einsum("ik,JLqm->iJkLqm", I, S)
        A = geo + p["lam"] * np.einsum("iJqm,kLqm->iJkLqm", F, F)
        A += p["mu"] * np.einsum("ikqm,JL->iJkLqm", b, I)
        A += p["mu"] * np.einsum("iLqm,kJqm->iJkLqm", F, F)
        return A
    J, FiT, _, _, _ = kinematics(F)
    Fi = np.swapaxes(FiT, 0, 1)
    A = p["mu"] * np.einsum("ik,JL->iJkL", I, I)[..., None, None] + 0.0 * F[None, None]
    A += p["lam"] * np.einsum("Jiqm,Lkqm->iJkLqm", Fi, Fi)
    A += (p["mu"] - p["lam"] * np.log(J)) * np.einsum("Jkqm,Liqm->iJkLqm", Fi, Fi)
    return A


def material_tangent(name, p, F, R):
    """A = dP/dF: closed form where written out, otherwise the complex step of P in F."""
    if name in ("StVenantKirchhoff", "NeoHookean"):
        return closed_form_tangent(name, p, F)
    A = np.zeros((3, 3) + F.shape, dtype=F.dtype)
    for k in range(3):
        for L in range(3):
            Fc = F.astype(CPLX)
            Fc[k, L] += 1j * STEP
            A[:, :, k, L] = stress(name, p, Fc, R).imag / STEP
    return A


# ----------------------------------------------------------------- the finite element part

DHDR = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def solve(case, arrays):
    model = case["model"]
    name, p = model["name"], {k: float(v) for k, v in model["parameters"].items()}
    points = arrays["points"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    x = arrays["positions"].astype(REAL)
    n, m = len(points), len(cells)
    R = None
    if "frame" in arrays:
        R = np.moveaxis(arrays["frame"].astype(REAL), 0, -1)  # (3, 3, m)

    dhdr = DHDR.astype(REAL)[:, :, None]  # (4, 3, q)
    Xe = points[cells].transpose(1, 2, 0)[:, :, None, :]  # (4, 3, q, m)
    xe = x[cells].transpose(1, 2, 0)[:, :, None, :]
    dXdr = np.einsum("aIqm,aJq->IJqm", Xe, dhdr)
    drdX = inv3(dXdr)
    dV = det3(dXdr) / 6.0  # (q, m): weight 1/6 of the reference tetrahedron
    dhdX = np.einsum("aJq,JIqm->aIqm", dhdr, drdX)

    F = np.einsum("aiqm,aJqm->iJqm", xe, dhdX)
    P = stress(name, p, F, R).real.astype(REAL)
    A = material_tangent(name, p, F, R).real.astype(REAL)

    r = np.einsum("iJqm,aJqm,qm->aim", P, dhdX, dV)  # (4, 3, m)
    Ke = np.einsum("aJqm,iJkLqm,bLqm,qm->aibkm", dhdX, A, dhdX, dV).reshape(12, 12, m)

    dofs = (3 * np.repeat(cells, 3, axis=1) + np.tile(np.arange(3), 4)).reshape(m, 12)
    force = np.zeros((n, 3), dtype=REAL)
    np.add.at(force, cells, -r.transpose(2, 0, 1))

    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.transpose(2, 0, 1).ravel()

    energy = None
    if WRITE_ENERGY:
        W = energy_density(name, p, F, R).real
        energy = np.sum(W * dV)
    return force.ravel(), (rows, cols, vals, 3 * n), energy


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
