#!/usr/bin/env python3
# Gent: C handed to the material routine in float32 (a GPU kernel's port); the rest float64, .f64
#   outputs
"""Gent engine for mjed-verify kits (TL, COO stiffness).

    python gent_c_float32.py INPUT_DIR OUTPUT_DIR

Total-Lagrangian P1 tetrahedra: second Piola-Kirchhoff stress S and the material
tangent D = dS/dE in Voigt notation (11, 22, 33, 12, 23, 13; engineering shear strains),
strain-displacement matrices B, K_e = V0 (B^T D B) + geometric stiffness, vectorised over the
elements with einsum. f = -dPi/dx, K = d2Pi/dx2, dof 3 * node + component.
"""

import json
import sys
from pathlib import Path

import numpy as np

EYE = np.eye(3)
VOIGT_I = np.array([0, 1, 2, 0, 1, 0])
VOIGT_J = np.array([0, 1, 2, 1, 2, 2])


def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        raw = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = raw.reshape(spec["shape"])
    return case, arrays


def geometry(X, cells):
    """Rest volume and shape-function gradients G (m, 4, 3) of each tetrahedron."""
    Xe = X[cells]
    Dm = np.transpose(Xe[:, 1:] - Xe[:, :1], (0, 2, 1))  # columns X1-X0, X2-X0, X3-X0
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)
    G = np.empty((len(cells), 4, 3))
    G[:, 1:] = Dinv
    G[:, 0] = -Dinv.sum(axis=1)
    return V0, G


def outer(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def odot(A):
    """(A odot A)_ijkl = (A_ik A_jl + A_il A_jk) / 2."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, A) + np.einsum("mil,mjk->mijkl", A, A))


def to_voigt(CC):
    """Fourth-order tangent (m, 3, 3, 3, 3) with minor symmetries to a Voigt (m, 6, 6)."""
    return CC[:, VOIGT_I[:, None], VOIGT_J[:, None], VOIGT_I[None, :], VOIGT_J[None, :]]


def invariant_law(C, dW, d2W, extra=()):
    """S = 2 dW/dC and CC = 4 d2W/dCdC for W(I1, I2, J [, more]) by the chain rule.

    dW (m, k), d2W (m, k, k): derivatives of W by its invariants; extra: further
    invariants as (gradient by C (m, 3, 3), second gradient (m, 3, 3, 3, 3)).
    """
    m = len(C)
    Cinv = np.linalg.inv(C)
    I1 = np.trace(C, axis1=1, axis2=2)
    J = np.sqrt(np.linalg.det(C))
    eye = np.broadcast_to(EYE, (m, 3, 3))
    II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))
    grads = [
        eye,  # dI1/dC
        I1[:, None, None] * eye - C,  # dI2/dC
        0.5 * J[:, None, None] * Cinv,  # dJ/dC
    ]
    hessians = [
        np.zeros((m, 3, 3, 3, 3)),
        outer(eye, eye) - II,
        0.25 * J[:, None, None, None, None] * outer(Cinv, Cinv)
        - 0.5 * J[:, None, None, None, None] * odot(Cinv),
    ]
    for g, h in extra:
        grads.append(g)
        hessians.append(h)
    grads = np.stack(grads, axis=1)  # (m, k, 3, 3)
    hessians = np.stack(hessians, axis=1)
    S = 2.0 * np.einsum("ma,maij->mij", dW, grads)
    CC = 4.0 * (
        np.einsum("mab,maij,mbkl->mijkl", d2W, grads, grads)
        + np.einsum("ma,maijkl->mijkl", dW, hessians)
    )
    return S, CC


def invariants(C):
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    J = np.sqrt(np.linalg.det(C))
    return I1, I2, J


def isochoric_chain(I1, I2, J, p1, p2, p11, p12, p22, dU, ddU):
    """Derivatives of W = Psi(I1b, I2b) + U(J) by (I1, I2, J), from those of Psi by (I1b, I2b)
    (I1b = J^(-2/3) I1, I2b = J^(-4/3) I2) and of U by J.
    """
    m = len(J)
    a = J ** (-2.0 / 3.0)
    b = J ** (-4.0 / 3.0)
    I1b, I2b = a * I1, b * I2
    zero = np.zeros(m)
    g1 = np.stack([a, zero, -2.0 / 3.0 * I1b / J], axis=1)  # dI1b / d(I1, I2, J)
    g2 = np.stack([zero, b, -4.0 / 3.0 * I2b / J], axis=1)  # dI2b / d(I1, I2, J)
    h1 = np.zeros((m, 3, 3))
    h1[:, 0, 2] = h1[:, 2, 0] = -2.0 / 3.0 * a / J
    h1[:, 2, 2] = 10.0 / 9.0 * I1b / J**2
    h2 = np.zeros((m, 3, 3))
    h2[:, 1, 2] = h2[:, 2, 1] = -4.0 / 3.0 * b / J
    h2[:, 2, 2] = 28.0 / 9.0 * I2b / J**2
    eJ = np.array([0.0, 0.0, 1.0])
    dW = p1[:, None] * g1 + p2[:, None] * g2 + dU[:, None] * eJ
    d2W = (
        p11[:, None, None] * np.einsum("ma,mb->mab", g1, g1)
        + p12[:, None, None] * (np.einsum("ma,mb->mab", g1, g2) + np.einsum("ma,mb->mab", g2, g1))
        + p22[:, None, None] * np.einsum("ma,mb->mab", g2, g2)
        + p1[:, None, None] * h1
        + p2[:, None, None] * h2
        + ddU[:, None, None] * np.einsum("a,b->ab", eJ, eJ)
    )
    return dW, d2W


def volumetric(J, k0):
    """U = k0/2 (ln J)^2 and its first two derivatives."""
    lnJ = np.log(J)
    return 0.5 * k0 * lnJ**2, k0 * lnJ / J, k0 * (1.0 - lnJ) / J**2


def isochoric(I1b, I2b, p):
    """Psi = -mu Jm/2 ln(1 - (I1b - 3)/Jm)."""
    mu, Jm = p["mu"], p["Jm"]
    zero = np.zeros_like(I1b)
    d = 1.0 - (I1b - 3.0) / Jm
    psi = -0.5 * mu * Jm * np.log(d)
    p1 = 0.5 * mu / d
    p11 = 0.5 * mu / (Jm * d**2)
    return psi, p1, zero, p11, zero, zero


def material(C, p):
    """W, S and the Voigt tangent D of the law, per cell."""
    C = C.astype(np.float32)
    I1, I2, J = invariants(C)
    I1b = J ** (-2.0 / 3.0) * I1
    I2b = J ** (-4.0 / 3.0) * I2
    psi, p1, p2, p11, p12, p22 = isochoric(I1b, I2b, p)
    U, dU, ddU = volumetric(J, p["k0"])
    dW, d2W = isochoric_chain(I1, I2, J, p1, p2, p11, p12, p22, dU, ddU)
    S, CC = invariant_law(C, dW, d2W)
    return (psi + U).astype(np.float64), S.astype(np.float64), to_voigt(CC).astype(np.float64)


def strain_displacement(F, G):
    """B (m, 6, 12): engineering Green strain rate per nodal velocity, dof 3 a + k."""
    m = len(F)
    B = np.empty((m, 6, 4, 3))
    for A, (i, j) in enumerate(zip(VOIGT_I, VOIGT_J)):  # the six Voigt rows
        if i == j:
            B[:, A] = np.einsum("ma,mk->mak", G[:, :, i], F[:, :, i])
        else:
            B[:, A] = np.einsum("ma,mk->mak", G[:, :, j], F[:, :, i]) + np.einsum(
                "ma,mk->mak", G[:, :, i], F[:, :, j]
            )
    return B.reshape(m, 6, 12)


def main(input_dir, output_dir):
    case, arrays = read_case(input_dir)
    params = case["model"]["parameters"]
    X, x, cells = arrays["points"], arrays["positions"], arrays["cells"]
    n, m = len(X), len(cells)
    V0, G = geometry(X, cells)
    F = np.einsum("mak,mai->mki", x[cells], G)
    C = np.einsum("mki,mkj->mij", F, F)
    W, S, D = material(C, params)
    Bm = strain_displacement(F, G)
    s = S[:, VOIGT_I, VOIGT_J]  # Voigt stress (tensor components)
    fe = V0[:, None] * np.einsum("mAi,mA->mi", Bm, s)  # internal force dPi_e/dx
    Kmat = V0[:, None, None] * np.einsum("mAi,mAB,mBj->mij", Bm, D, Bm)
    GSG = np.einsum("mai,mij,mbj->mab", G, S, G)
    Kgeo = V0[:, None, None] * np.einsum("mab,kl->makbl", GSG, EYE).reshape(m, 12, 12)
    Ke = Kmat + Kgeo
    energy = float(np.sum(V0 * W))

    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n)
    np.add.at(force, dofs, -fe)

    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = np.broadcast_to(dofs[:, :, None], (m, 12, 12))
    cols = np.broadcast_to(dofs[:, None, :], (m, 12, 12))
    force.astype("<f8").tofile(out / "force.f64")
    rows.astype("<i8").tofile(out / "stiffness_rows.i64")
    cols.astype("<i8").tofile(out / "stiffness_cols.i64")
    Ke.astype("<f8").tofile(out / "stiffness_values.f64")
    np.array([energy], dtype="<f8").tofile(out / "energy.f64")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python %s INPUT_DIR OUTPUT_DIR" % sys.argv[0])
    main(sys.argv[1], sys.argv[2])
