#!/usr/bin/env python3
# MISTAKE: edge ids of the per-pair edge list reshaped (m, 6) where the list was built pair-
# major (6 blocks of m cells): each cell's off-diagonal blocks accumulated into other cells'
# edges; force right, stiffness wrong (no energy written).
"""SOFA-style hyperelastic tetrahedral force field with edge-based stiffness (NumPy port).

Usage: python ENGINE INPUT_DIR OUTPUT_DIR. Per tetrahedron: rest shape vectors dN_a (rows of
the inverse rest edge matrix), V0, F, C, J; a material object with spk(C, J, p) -> S and
apply_elasticity(C, H, p) -> dS (the elasticity tensor dS/dE applied to a symmetric direction
H = dE, evaluated as the complex-step derivative of the stress along dC = 2 H; Ogden through
the eigen-decomposition of C). Nodal force f_a = -V0 F S dN_a; stiffness K = d2W/dx2 assembled
from per-edge and per-vertex 3x3 blocks (the kit's sign, the opposite of addKToMatrix).
"""

import json
import os
import sys

import numpy as np
import scipy.sparse as sp

DTYPE = np.float64
LAYOUT = "coo"
WRITE_ENERGY = False
HSTEP = 1e-30


def det3(A):
    return (
        A[..., 0, 0] * (A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1])
        - A[..., 0, 1] * (A[..., 1, 0] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 0])
        + A[..., 0, 2] * (A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0])
    )


def inv3(A):
    cof = np.empty_like(A)
    for i in range(3):
        for j in range(3):
            r = [k for k in range(3) if k != i]
            c = [k for k in range(3) if k != j]
            minor = (
                A[..., r[0], c[0]] * A[..., r[1], c[1]] - A[..., r[0], c[1]] * A[..., r[1], c[0]]
            )
            cof[..., j, i] = (-1) ** (i + j) * minor
    return cof / det3(A)[..., None, None]


def trace(A):
    return A[..., 0, 0] + A[..., 1, 1] + A[..., 2, 2]


def invariants(C):
    I1 = trace(C)
    I2 = 0.5 * (I1 * I1 - trace(C @ C))
    J = np.sqrt(det3(C))
    return I1, I2, J


class IsochoricInvariantMaterial:
    """W = Psi(I1b, I2b) + k0/2 (ln J)^2; S = 2 (Psi_1 dI1b/dC + Psi_2 dI2b/dC + U' dJ/dC)."""

    def psi(self, t1, t2, p):
        raise NotImplementedError

    def dpsi(self, t1, t2, p):
        raise NotImplementedError

    def energy(self, C, J, p):
        I1, I2, J = invariants(C)
        I1b = J ** (-2.0 / 3.0) * I1
        I2b = J ** (-4.0 / 3.0) * I2
        return self.psi(I1b, I2b, p) + 0.5 * p["k0"] * np.log(J) ** 2

    def spk(self, C, J, p):
        I1, I2, J = invariants(C)
        eye = np.eye(3, dtype=DTYPE)
        Ci = inv3(C)
        I1b = J ** (-2.0 / 3.0) * I1
        I2b = J ** (-4.0 / 3.0) * I2
        w1, w2 = self.dpsi(I1b, I2b, p)
        dI1b = J[:, None, None] ** (-2.0 / 3.0) * (eye - I1[:, None, None] / 3.0 * Ci)
        dI2b = J[:, None, None] ** (-4.0 / 3.0) * (
            I1[:, None, None] * eye - C - 2.0 / 3.0 * I2[:, None, None] * Ci
        )
        dU = p["k0"] * np.log(J) / J
        S = 2.0 * (w1[:, None, None] * dI1b + np.asarray(w2)[..., None, None] * dI2b)
        return S + (dU * J)[:, None, None] * Ci

    def apply_elasticity(self, C, H, p):
        Cc = C + 1j * HSTEP * 2.0 * H
        return self.spk(Cc, None, p).imag / HSTEP


class MooneyRivlin(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        return p["c1"] * (t1 - 3.0) + p["c2"] * (t2 - 3.0)

    def dpsi(self, t1, t2, p):
        return p["c1"] + 0 * t1, p["c2"] + 0 * t1


class VerondaWestmann(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        c1, c2 = p["c1"], p["c2"]
        return c1 * (np.exp(c2 * (t1 - 3.0)) - 1.0) - 0.5 * c1 * c2 * (t2 - 3.0)

    def dpsi(self, t1, t2, p):
        c1, c2 = p["c1"], p["c2"]
        return c1 * c2 * np.exp(c2 * (t1 - 3.0)), -0.5 * c1 * c2 + 0 * t1


AB_COEFFS = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


class ArrudaBoyce(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        mu, N = p["mu"], p["N"]
        return mu * sum(
            c * N ** (-i) * (t1 ** (i + 1) - 3.0 ** (i + 1)) for i, c in enumerate(AB_COEFFS)
        )

    def dpsi(self, t1, t2, p):
        mu, N = p["mu"], p["N"]
        w1 = mu * sum(c * N ** (-i) * (i + 1) * t1**i for i, c in enumerate(AB_COEFFS))
        return w1, 0 * t1


class Yeoh(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        d = t1 - 3.0
        return p["c10"] * d + p["c20"] * d**2 + p["c30"] * d**3

    def dpsi(self, t1, t2, p):
        d = t1 - 3.0
        return p["c10"] + 2.0 * p["c20"] * d + 3.0 * p["c30"] * d**2, 0 * t1


class Gent(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        mu, Jm = p["mu"], p["Jm"]
        return -0.5 * mu * Jm * np.log(1.0 - (t1 - 3.0) / Jm)

    def dpsi(self, t1, t2, p):
        mu, Jm = p["mu"], p["Jm"]
        return 0.5 * mu / (1.0 - (t1 - 3.0) / Jm), 0 * t1


class Demiray(IsochoricInvariantMaterial):
    def psi(self, t1, t2, p):
        a, b = p["a"], p["b"]
        return a / (2.0 * b) * (np.exp(b * (t1 - 3.0)) - 1.0)

    def dpsi(self, t1, t2, p):
        a, b = p["a"], p["b"]
        return 0.5 * a * np.exp(b * (t1 - 3.0)), 0 * t1


class NeoHookean:
    def energy(self, C, J, p):
        I1, I2, J = invariants(C)
        lnJ = np.log(J)
        return 0.5 * p["mu"] * (I1 - 3.0) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ**2

    def spk(self, C, J, p):
        I1, I2, J = invariants(C)
        eye = np.eye(3, dtype=DTYPE)
        coef = -p["mu"] + p["lam"] * np.log(J)
        return p["mu"] * eye + coef[:, None, None] * inv3(C)

    def apply_elasticity(self, C, H, p):
        Cc = C + 1j * HSTEP * 2.0 * H
        return self.spk(Cc, None, p).imag / HSTEP


class StVenantKirchhoff:
    def energy(self, C, J, p):
        E = 0.5 * (C - np.eye(3, dtype=DTYPE))
        return 0.5 * p["lam"] * trace(E) ** 2 + p["mu"] * trace(E @ E)

    def spk(self, C, J, p):
        eye = np.eye(3, dtype=DTYPE)
        E = 0.5 * (C - eye)
        return p["lam"] * trace(E)[:, None, None] * eye + 2.0 * p["mu"] * E

    def apply_elasticity(self, C, H, p):
        eye = np.eye(3, dtype=DTYPE)
        return p["lam"] * trace(H)[:, None, None] * eye + 2.0 * p["mu"] * H


class Costa:
    def __init__(self, frames):
        self.R = frames

    def bmatrix(self, p):
        return np.array(
            [
                [p["b_ff"], p["b_fs"], p["b_fn"]],
                [p["b_fs"], p["b_ss"], p["b_sn"]],
                [p["b_fn"], p["b_sn"], p["b_nn"]],
            ],
            dtype=DTYPE,
        )

    def energy(self, C, J, p):
        I1, I2, J = invariants(C)
        R = self.R
        Ef = np.swapaxes(R, 1, 2) @ (0.5 * (C - np.eye(3, dtype=DTYPE))) @ R
        Q = np.sum(self.bmatrix(p) * Ef * Ef, axis=(1, 2))
        k0 = p["k0"]
        return 0.5 * p["a"] * (np.exp(J ** (-4.0 / 3.0) * Q) - 1.0) + k0 * (J * np.log(J) - J + 1.0)

    def spk(self, C, J, p):
        I1, I2, J = invariants(C)
        R = self.R
        Ci = inv3(C)
        Ef = np.swapaxes(R, 1, 2) @ (0.5 * (C - np.eye(3, dtype=DTYPE))) @ R
        B = self.bmatrix(p)
        Q = np.sum(B * Ef * Ef, axis=(1, 2))
        dQdC = R @ (B * Ef) @ np.swapaxes(R, 1, 2)
        g = J ** (-4.0 / 3.0)
        dQh = g[:, None, None] * (dQdC - 2.0 / 3.0 * Q[:, None, None] * Ci)
        S = p["a"] * np.exp(g * Q)[:, None, None] * dQh
        return S + (p["k0"] * J * np.log(J))[:, None, None] * Ci

    def apply_elasticity(self, C, H, p):
        Cc = C + 1j * HSTEP * 2.0 * H
        return self.spk(Cc, None, p).imag / HSTEP


class Ogden:
    """W = mu/alpha^2 (J^(-alpha/3) sum lambda_i^(alpha/2) - 3) + k0/2 (ln J)^2."""

    def eig(self, C):
        lam, Q = np.linalg.eigh(C)
        return lam, Q

    def energy(self, C, J, p):
        mu, al = p["mu"], p["alpha"]
        lam, Q = self.eig(C)
        J = np.sqrt(np.prod(lam, axis=1))
        P = np.sum(lam ** (0.5 * al), axis=1)
        return mu / al**2 * (J ** (-al / 3.0) * P - 3.0) + 0.5 * p["k0"] * np.log(J) ** 2

    def parts(self, C, p):
        mu, al = p["mu"], p["alpha"]
        lam, Q = self.eig(C)
        J = np.sqrt(np.prod(lam, axis=1))
        pw = 0.5 * al
        P = np.sum(lam**pw, axis=1)
        g = J ** (-al / 3.0)
        return mu / al**2, al, pw, lam, Q, J, P, g

    def spk(self, C, J, p):
        c, al, pw, lam, Q, J, P, g = self.parts(C, p)
        Qt = np.swapaxes(Q, 1, 2)
        Cp = (Q * (pw * lam ** (pw - 1.0))[:, None, :]) @ Qt
        Ci = (Q * (1.0 / lam)[:, None, :]) @ Qt
        S = 2.0 * c * g[:, None, None] * (Cp - (al / 6.0) * P[:, None, None] * Ci)
        return S + (p["k0"] * np.log(J))[:, None, None] * Ci

    def apply_elasticity(self, C, H, p):
        c, al, pw, lam, Q, J, P, g = self.parts(C, p)
        Qt = np.swapaxes(Q, 1, 2)
        dC = 2.0 * H
        Ci = (Q * (1.0 / lam)[:, None, :]) @ Qt
        Cp = (Q * (pw * lam ** (pw - 1.0))[:, None, :]) @ Qt
        # Daleckii-Krein: d(C^(pw-1)) = Q (G o (Q^T dC Q)) Q^T, G the divided differences
        fl = pw * lam ** (pw - 1.0)
        dfl = pw * (pw - 1.0) * lam ** (pw - 2.0)
        li, lj = lam[:, :, None], lam[:, None, :]
        fi, fj = fl[:, :, None], fl[:, None, :]
        close = np.abs(li - lj) <= 1e-6 * np.maximum(np.abs(li), np.abs(lj))
        den = np.where(close, 1.0, li - lj)
        G = np.where(close, 0.5 * (dfl[:, :, None] + dfl[:, None, :]), (fi - fj) / den)
        dCp = Q @ (G * (Qt @ dC @ Q)) @ Qt
        dCi = -Ci @ dC @ Ci
        trCi = np.sum(Ci * dC, axis=(1, 2))
        dP = np.sum(Cp * dC, axis=(1, 2))
        dg = -(al / 6.0) * g * trCi
        dS = (
            2.0
            * c
            * (
                dg[:, None, None] * (Cp - (al / 6.0) * P[:, None, None] * Ci)
                + g[:, None, None]
                * (dCp - (al / 6.0) * (dP[:, None, None] * Ci + P[:, None, None] * dCi))
            )
        )
        dS += p["k0"] * (0.5 * trCi[:, None, None] * Ci + np.log(J)[:, None, None] * dCi)
        return dS


def read_case(folder):
    with open(os.path.join(folder, "case.json")) as fh:
        case = json.load(fh)
    arrays = {}
    for name, spec in case["arrays"].items():
        data = np.fromfile(os.path.join(folder, spec["file"]), dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return case, arrays


def make_material(name, arrays):
    if name == "Costa":
        return Costa(np.asarray(arrays["frame"], dtype=DTYPE).reshape(-1, 3, 3))
    table = {
        "NeoHookean": NeoHookean,
        "StVenantKirchhoff": StVenantKirchhoff,
        "MooneyRivlin": MooneyRivlin,
        "VerondaWestmann": VerondaWestmann,
        "ArrudaBoyce": ArrudaBoyce,
        "Yeoh": Yeoh,
        "Gent": Gent,
        "Demiray": Demiray,
        "Ogden": Ogden,
    }
    return table[name]()


def rest_shape_vectors(X, cells):
    X0 = X[cells[:, 0]]
    M = np.stack([X[cells[:, 1]] - X0, X[cells[:, 2]] - X0, X[cells[:, 3]] - X0], axis=2)
    V0 = det3(M) / 6.0
    Minv = inv3(M)
    dN = np.empty((len(cells), 4, 3), dtype=DTYPE)
    dN[:, 1:, :] = Minv
    dN[:, 0, :] = -Minv.sum(axis=1)
    return dN, V0


def edge_table(cells):
    """Unique edges (lo, hi) of the mesh and, per cell and local pair a < b, its edge id."""
    pairs = [(a, b) for a in range(4) for b in range(a + 1, 4)]
    ends = np.stack([np.stack([cells[:, a], cells[:, b]], axis=1) for a, b in pairs], axis=0)
    lohi = np.sort(ends, axis=2).reshape(-1, 2)
    edges, ids = np.unique(lohi, axis=0, return_inverse=True)
    return pairs, edges, ids.reshape(len(cells), len(pairs))


def main():
    src, dst = sys.argv[1], sys.argv[2]
    case, arrays = read_case(src)
    params = {k: float(v) for k, v in case["model"]["parameters"].items()}
    X = np.asarray(arrays["points"], dtype=DTYPE)
    x = np.asarray(arrays["positions"], dtype=DTYPE)
    cells = np.asarray(arrays["cells"], dtype=np.int64)
    n, m = len(X), len(cells)
    material = make_material(case["model"]["name"], arrays)

    dN, V0 = rest_shape_vectors(X, cells)
    F = np.einsum("cak,cai->cki", x[cells], dN)
    C = np.swapaxes(F, 1, 2) @ F
    J = det3(F)
    S = material.spk(C, J, params)

    # nodal forces f_a = -V0 F S dN_a
    fe = -V0[:, None, None] * np.einsum("cki,cij,caj->cak", F, S, dN)
    force = np.zeros((n, 3), dtype=DTYPE)
    np.add.at(force, cells, fe)

    # dS_bk for the direction of node b, component k: H = sym((F^T e_k) dN_b^T)
    FS_dN = {}
    for b in range(4):
        for k in range(3):
            g = F[:, k, :]
            H = 0.5 * (g[:, :, None] * dN[:, b, None, :] + dN[:, b, :, None] * g[:, None, :])
            FS_dN[b, k] = np.einsum("cij,caj->cai", material.apply_elasticity(C, H, params), dN)

    def block(a, b):
        Kab = np.zeros((m, 3, 3), dtype=DTYPE)
        geo = np.einsum("ci,cij,cj->c", dN[:, a], S, dN[:, b])
        for k in range(3):
            Kab[:, :, k] = np.einsum("cij,cj->ci", F, FS_dN[b, k][:, a])
            Kab[:, k, k] += geo
        return V0[:, None, None] * Kab

    pairs, edges, edge_ids = edge_table(cells)
    edge_blocks = np.zeros((len(edges), 3, 3), dtype=DTYPE)
    for p_index, (a, b) in enumerate(pairs):
        Kab = block(a, b)
        flip = cells[:, a] > cells[:, b]
        Kab = np.where(flip[:, None, None], np.swapaxes(Kab, 1, 2), Kab)
        np.add.at(edge_blocks, edge_ids[:, p_index], Kab)
    vertex_blocks = np.zeros((n, 3, 3), dtype=DTYPE)
    for a in range(4):
        np.add.at(vertex_blocks, cells[:, a], block(a, a))

    # global matrix from the edge blocks (lo, hi), their transposes (hi, lo) and vertex blocks
    comp = np.arange(3)
    bi, bj = np.meshgrid(comp, comp, indexing="ij")
    lo, hi = edges[:, 0], edges[:, 1]
    verts = np.arange(n)
    rows = np.concatenate(
        [
            (3 * lo[:, None, None] + bi).ravel(),
            (3 * hi[:, None, None] + bi).ravel(),
            (3 * verts[:, None, None] + bi).ravel(),
        ]
    )
    cols = np.concatenate(
        [
            (3 * hi[:, None, None] + bj).ravel(),
            (3 * lo[:, None, None] + bj).ravel(),
            (3 * verts[:, None, None] + bj).ravel(),
        ]
    )
    vals = np.concatenate(
        [edge_blocks.ravel(), np.swapaxes(edge_blocks, 1, 2).ravel(), vertex_blocks.ravel()]
    )

    os.makedirs(dst, exist_ok=True)
    ext = ".f32" if DTYPE == np.float32 else ".f64"
    force.astype(DTYPE).tofile(os.path.join(dst, "force" + ext))
    if LAYOUT == "dense":
        K = np.zeros((3 * n, 3 * n), dtype=DTYPE)
        np.add.at(K, (rows, cols), vals)
        K.tofile(os.path.join(dst, "stiffness" + ext))
    elif LAYOUT == "coo":
        rows.astype(np.int64).tofile(os.path.join(dst, "stiffness_rows.i64"))
        cols.astype(np.int64).tofile(os.path.join(dst, "stiffness_cols.i64"))
        vals.astype(DTYPE).tofile(os.path.join(dst, "stiffness_values" + ext))
    else:
        K = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n))
        K.sum_duplicates()
        K.indptr.astype(np.int64).tofile(os.path.join(dst, "stiffness_indptr.i64"))
        K.indices.astype(np.int64).tofile(os.path.join(dst, "stiffness_indices.i64"))
        K.data.astype(DTYPE).tofile(os.path.join(dst, "stiffness_values" + ext))
    if WRITE_ENERGY:
        W = material.energy(C, J, params)
        energy = np.sum(V0 * W)
        np.array([energy], dtype=DTYPE).tofile(os.path.join(dst, "energy" + ext))


if __name__ == "__main__":
    main()
