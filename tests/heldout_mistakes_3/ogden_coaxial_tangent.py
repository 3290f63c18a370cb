#!/usr/bin/env python3
# Ogden: coaxial tangent: d(C^(alpha/2 - 1))/dC with the eigenvectors held fixed (only
#   f'(lambda_i) on i = j; the divided differences between eigenvalues dropped)
"""Ogden engine for mjed-verify kits (TL, COO stiffness).

    python ogden_coaxial_tangent.py INPUT_DIR OUTPUT_DIR

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


def material(C, p):
    """W = mu/alpha^2 (J^(-alpha/3) P - 3) + k0/2 (ln J)^2, P = tr C^(alpha/2) = sum of the
    eigenvalues of C to the power alpha/2 (the principal stretches to the power alpha).
    """
    mu, alpha, k0 = p["mu"], p["alpha"], p["k0"]
    lam, N = np.linalg.eigh(C)  # eigenvalues of C, eigenvectors in the columns of N
    h = 0.5 * alpha
    P = np.sum(lam**h, axis=1)
    fl = h * lam ** (h - 1.0)  # f(lambda), dP/dC = f(C)
    dP = np.einsum("mpi,mi,mqi->mpq", N, fl, N)
    # d f(C) / dC in the principal frame, eigenvectors held fixed: f'(lambda_i) on i = j
    div = np.einsum("mi,ij->mij", h * (h - 1.0) * lam ** (h - 2.0), np.eye(3))
    T = np.einsum("mij,mpi,mri,mqj,msj->mpqrs", div, N, N, N, N)
    d2P = 0.5 * (T + np.transpose(T, (0, 1, 2, 4, 3)))
    J = np.sqrt(np.prod(lam, axis=1))
    lnJ = np.log(J)
    c = mu / alpha**2
    Ja = J ** (-alpha / 3.0)
    W = c * (Ja * P - 3.0) + 0.5 * k0 * lnJ**2
    m = len(J)
    dW = np.zeros((m, 4))  # by (I1, I2, J, P)
    d2W = np.zeros((m, 4, 4))
    dW[:, 3] = c * Ja
    dW[:, 2] = -alpha / 3.0 * c * Ja * P / J + k0 * lnJ / J
    d2W[:, 2, 3] = d2W[:, 3, 2] = -alpha / 3.0 * c * Ja / J
    d2W[:, 2, 2] = alpha / 3.0 * (alpha / 3.0 + 1.0) * c * Ja * P / J**2 + k0 * (1.0 - lnJ) / J**2
    S, CC = invariant_law(C, dW, d2W, extra=[(dP, d2P)])
    return W, S, to_voigt(CC)


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
