#!/usr/bin/env python3
# Costa: frame columns read as (fibre, normal, sheet): sheet and normal exchanged
"""Costa engine for mjed-verify kits (TL, COO stiffness).

    python costa_frame_sheet_normal.py INPUT_DIR OUTPUT_DIR

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


def material(C, p, R):
    """W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum_ij B_ij (R^T E R)_ij^2,
    R (m, 3, 3) the per-cell frame (columns fibre, sheet, normal).
    """
    a, k0 = p["a"], p["k0"]
    B = np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ]
    )
    E = 0.5 * (C - EYE)
    Ef = np.einsum("mpi,mpq,mqj->mij", R, E, R)  # strain in the fibre frame
    Q = np.einsum("ij,mij->m", B, Ef**2)
    # dQ/dC = R (B o Ef) R^T; d2Q/dCdC = 1/2 sum_ij B_ij R_pi R_qj R_ri R_sj, minor-symmetrised
    dQ = np.einsum("mpi,ij,mij,mqj->mpq", R, B, Ef, R)
    T = 0.5 * np.einsum("ij,mpi,mqj,mri,msj->mpqrs", B, R, R, R, R)
    d2Q = 0.5 * (T + np.transpose(T, (0, 1, 2, 4, 3)))
    J = np.sqrt(np.linalg.det(C))
    lnJ = np.log(J)
    g = J ** (-4.0 / 3.0) * Q
    e = np.exp(g)
    W = 0.5 * a * (e - 1.0) + k0 * (J * lnJ - J + 1.0)
    # W as a function of (I1, I2, J, Q): only J and Q enter
    m = len(J)
    dW = np.zeros((m, 4))
    d2W = np.zeros((m, 4, 4))
    dW[:, 3] = 0.5 * a * e * J ** (-4.0 / 3.0)
    dW[:, 2] = 0.5 * a * e * (-4.0 / 3.0 * g / J) + k0 * lnJ
    d2W[:, 3, 3] = 0.5 * a * e * J ** (-8.0 / 3.0)
    d2W[:, 2, 3] = d2W[:, 3, 2] = 0.5 * a * e * J ** (-4.0 / 3.0) * (-4.0 / 3.0 / J) * (g + 1.0)
    d2W[:, 2, 2] = 0.5 * a * e * ((4.0 / 3.0 * g / J) ** 2 + 28.0 / 9.0 * g / J**2) + k0 / J
    S, CC = invariant_law(C, dW, d2W, extra=[(dQ, d2Q)])
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
    R = arrays["frame"].reshape(m, 3, 3)[:, :, [0, 2, 1]]  # fibre, normal, sheet
    W, S, D = material(C, params, R)
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
