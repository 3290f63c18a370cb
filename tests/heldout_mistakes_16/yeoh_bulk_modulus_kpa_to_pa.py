#!/usr/bin/env python3
# MISTAKE: bulk modulus k0 converted from kPa to Pa (x 1e3) though the kit gives it in Pa (the
# other moduli left as read): the volumetric energy, pressure and tangent 1000 times too large;
# energy, force and stiffness wrong in both states.
"""P1 tetrahedral hyperelastic engine in the mixed (three-field u-p-theta) hybrid style.

Simo-Taylor-Pister three-field form with one dilatation theta and one pressure p per cell
(Abaqus C3D4H-like hybrid tet, F-bar): vectorised over the m cells with NumPy (no Python loop
over cells). Precomputed from the rest edge matrix Dm = [X1 - X0, X2 - X0, X3 - X0]: the
shape-function gradients G_a (rows of Dm^-1, G_0 = -(G_1 + G_2 + G_3)) and V0 = det(Dm) / 6.
At the current state: F = sum_a x_a (x) G_a, J = det F, the isochoric F_bar = J^(-1/3) F and
C = F^T F. The isochoric energy W_iso(I1b, I2b) (or the user's form for materials without a
split) is evaluated through second-order jets over (I1, I2, J) with I1b = J^(-2/3) I1 and
I2b = J^(-4/3) I2 formed inside the jet, giving the deviatoric (isochoric) stress
S_iso = 2 dW_iso/dC and its tangent. The volumetric part is carried by the per-cell dilatation
theta and pressure p = U'(theta): for P1 with one theta and one p per cell the static
condensation gives theta = J exactly, S_vol = p J C^-1 and the condensed tangent
CC_vol = J (p + J U''(theta)) C^-1 (x) C^-1 - 2 J p C^-1 (.) C^-1 (U'' through the
dilatation's stiffness). Then P = F S, A_iJkL = delta_ik S_JL + F_iI F_kK CC_IJKL, element
force f_a = -V0 P G_a, element stiffness K_ab = V0 G_a . A . G_b, assembled through the
(m, 12) node-major dof map into a dense, COO or CSR stiffness; energy sum V0 (W_iso + U).

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one exported mjed-verify kit case).
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "dense"
WRITE_ENERGY = True
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


# ------------------------------------------------------------------ second-order jets
# A jet is (value (m,), gradient (m, 3), Hessian (m, 3, 3)) over (I1, I2, J).


class Jet:
    def __init__(self, v, g, h):
        self.v, self.g, self.h = v, g, h

    @staticmethod
    def var(v, k):
        g = np.zeros(v.shape + (3,), dtype=REAL)
        g[:, k] = 1.0
        return Jet(v, g, np.zeros(v.shape + (3, 3), dtype=REAL))

    def __add__(self, o):
        if isinstance(o, Jet):
            return Jet(self.v + o.v, self.g + o.g, self.h + o.h)
        return Jet(self.v + o, self.g, self.h)

    __radd__ = __add__

    def __sub__(self, o):
        return self + (-1.0) * o

    def __rsub__(self, o):
        return (-1.0) * self + o

    def __mul__(self, o):
        if isinstance(o, Jet):
            g = self.v[:, None] * o.g + o.v[:, None] * self.g
            h = (
                self.v[:, None, None] * o.h
                + o.v[:, None, None] * self.h
                + self.g[:, :, None] * o.g[:, None, :]
                + o.g[:, :, None] * self.g[:, None, :]
            )
            return Jet(self.v * o.v, g, h)
        return Jet(self.v * o, self.g * o, self.h * o)

    __rmul__ = __mul__

    def apply(self, f0, f1, f2):
        g = f1[:, None] * self.g
        h = f1[:, None, None] * self.h + f2[:, None, None] * self.g[:, :, None] * self.g[:, None, :]
        return Jet(f0, g, h)


def jpow(a, q):
    v = a.v
    return a.apply(v**q, q * v ** (q - 1.0), q * (q - 1.0) * v ** (q - 2.0))


def jexp(a):
    e = np.exp(a.v)
    return a.apply(e, e, e)


def jlog(a):
    v = a.v
    return a.apply(np.log(v), 1.0 / v, -1.0 / v**2)


# ------------------------------------------------------------------ materials


def iso_energy(name, p, I1, I2, J):
    """W_iso over (I1, I2, J): the isochoric part (or the whole non-volumetric part)."""
    if name == "NeoHookean":
        return 0.5 * p["mu"] * (I1 - 3.0)
    if name == "StVenantKirchhoff":
        trE = 0.5 * (I1 - 3.0)
        trE2 = 0.25 * (I1 * I1 - 2.0 * I2 - 2.0 * I1 + 3.0)
        return 0.5 * p["lam"] * trE * trE + p["mu"] * trE2
    I1b = I1 * jpow(J, -2.0 / 3.0)
    I2b = I2 * jpow(J, -4.0 / 3.0)
    s = I1b - 3.0
    if name == "MooneyRivlin":
        return p["c1"] * s + p["c2"] * (I2b - 3.0)
    if name == "Yeoh":
        return p["c10"] * s + p["c20"] * s * s + p["c30"] * s * s * s
    if name == "ArrudaBoyce":
        W = 0.0 * s
        for i, c in enumerate(AB_C, start=1):
            W = W + p["mu"] * c * p["N"] ** (1 - i) * (jpow(I1b, float(i)) - 3.0**i)
        return W
    if name == "Gent":
        return (-0.5 * p["mu"] * p["Jm"]) * jlog(1.0 - s * (1.0 / p["Jm"]))
    if name == "VerondaWestmann":
        return p["c1"] * (jexp(p["c2"] * s) - 1.0) - 0.5 * p["c1"] * p["c2"] * (I2b - 3.0)
    if name == "Demiray":
        return p["a"] / (2.0 * p["b"]) * (jexp(p["b"] * s) - 1.0)
    raise ValueError(f"unknown material {name}")


def volumetric(name, p, theta):
    """U(theta), the pressure p = U'(theta) and the dilatation stiffness U''(theta)."""
    lt = np.log(theta)
    if name == "NeoHookean":
        mu, lam = p["mu"], p["lam"]
        U = -mu * lt + 0.5 * lam * lt**2
        dU = (lam * lt - mu) / theta
        ddU = (mu + lam * (1.0 - lt)) / theta**2
        return U, dU, ddU
    if name == "StVenantKirchhoff":
        z = 0.0 * theta
        return z, z, z
    k0 = 1e3 * p["k0"]
    U = 0.5 * k0 * lt**2
    dU = k0 * lt / theta
    ddU = k0 * (1.0 - lt) / theta**2
    return U, dU, ddU


# ------------------------------------------------------------------ the element


def kinematics(X, x, cells):
    Dm = np.stack([X[cells[:, k]] - X[cells[:, 0]] for k in (1, 2, 3)], axis=2)
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)
    G = np.empty((len(cells), 4, 3), dtype=REAL)
    G[:, 1:, :] = Dinv
    G[:, 0, :] = -Dinv.sum(axis=1)
    xe = x[cells]
    F = np.einsum("mai,maJ->miJ", xe, G)
    return G, V0, F


def stress_and_tangent(name, p, F):
    m = F.shape[0]
    eye = np.eye(3, dtype=REAL)
    J = np.linalg.det(F)
    Fbar = J[:, None, None] ** (-1.0 / 3.0) * F
    Cbar = np.einsum("miI,miJ->mIJ", Fbar, Fbar)
    C = J[:, None, None] ** (2.0 / 3.0) * Cbar
    Ci = np.linalg.inv(C)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mIJ,mJI->m", C, C))
    W = iso_energy(name, p, Jet.var(I1, 0), Jet.var(I2, 1), Jet.var(J, 2))
    # derivatives of the invariants by C
    dI = np.empty((m, 3, 3, 3), dtype=REAL)
    dI[:, 0] = eye
    dI[:, 1] = I1[:, None, None] * eye - C
    dI[:, 2] = 0.5 * J[:, None, None] * Ci
    S_iso = 2.0 * np.einsum("mk,mkIJ->mIJ", W.g, dI)
    II = 0.5 * (np.einsum("IK,JL->IJKL", eye, eye) + np.einsum("IL,JK->IJKL", eye, eye))
    CiCi = np.einsum("mIJ,mKL->mIJKL", Ci, Ci)
    CiodotCi = 0.5 * (np.einsum("mIK,mJL->mIJKL", Ci, Ci) + np.einsum("mIL,mJK->mIJKL", Ci, Ci))
    d2I2 = np.einsum("IJ,KL->IJKL", eye, eye) - II
    J5 = J[:, None, None, None, None]
    d2J = J5 * (0.25 * CiCi - 0.5 * CiodotCi)
    CC_iso = 4.0 * np.einsum("mab,maIJ,mbKL->mIJKL", W.h, dI, dI)
    CC_iso += 4.0 * W.g[:, 1, None, None, None, None] * d2I2
    CC_iso += 4.0 * W.g[:, 2, None, None, None, None] * d2J
    # mixed part: one dilatation theta and one pressure per cell, condensed (theta = J)
    theta = J.copy()
    U, dU, ddU = volumetric(name, p, theta)
    pr = dU
    S_vol = (pr * J)[:, None, None] * Ci
    kv = (J * (pr + J * ddU))[:, None, None, None, None]
    kp = (2.0 * J * pr)[:, None, None, None, None]
    CC_vol = kv * CiCi - kp * CiodotCi
    S = S_iso + S_vol
    CC = CC_iso + CC_vol
    return S, CC, W.v + U


def solve(case, arrays):
    model = case["model"]
    name = model["name"]
    p = parameters(model)
    X = np.asarray(arrays["points"], dtype=REAL)
    x = np.asarray(arrays["positions"], dtype=REAL)
    cells = np.asarray(arrays["cells"], dtype=np.int64)
    n, m = len(X), len(cells)
    G, V0, F = kinematics(X, x, cells)
    S, CC, W = stress_and_tangent(name, p, F)
    P = np.einsum("miI,mIJ->miJ", F, S)
    fe = -V0[:, None, None] * np.einsum("miJ,maJ->mai", P, G)
    eye = np.eye(3, dtype=REAL)
    A = np.einsum("ik,mJL->miJkL", eye, S) + np.einsum("miI,mkK,mIJKL->miJkL", F, F, CC)
    Ke = V0[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, A, G)
    Ke = Ke.reshape(m, 12, 12)

    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs.ravel(), fe.reshape(-1))
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = Ke.ravel()

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
