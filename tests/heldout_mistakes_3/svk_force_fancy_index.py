#!/usr/bin/env python3
# StVenantKirchhoff: force assembled with buffered fancy indexing force[dofs] -= fe (repeated nodes
#   added once)
"""St Venant-Kirchhoff engine for mjed-verify kits (TL, COO stiffness).

    python svk_force_fancy_index.py INPUT_DIR OUTPUT_DIR

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


def material(C, p):
    """W = lam/2 (tr E)^2 + mu tr(E^2): S = lam tr(E) I + 2 mu E, D in Voigt form."""
    mu, lam = p["mu"], p["lam"]
    E = 0.5 * (C - EYE)
    trE = np.trace(E, axis1=1, axis2=2)
    W = 0.5 * lam * trE**2 + mu * np.einsum("mij,mij->m", E, E)
    S = lam * trE[:, None, None] * EYE + 2.0 * mu * E
    ones = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    D = lam * np.outer(ones, ones) + mu * np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    return W, S, np.broadcast_to(D, (len(C), 6, 6))


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
    force[dofs] -= fe

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
