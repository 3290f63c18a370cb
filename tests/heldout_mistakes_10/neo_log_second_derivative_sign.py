#!/usr/bin/env python3
# Mistake: the hyper-dual logarithm written with the second derivative +1/a^2 (the minus of d2 ln
# a/da2 = -1/a^2 lost) in its e1 e2 part: the curvature of every ln J term, - mu ln J + lam/2 (ln
# J)^2, enters the stiffness with the wrong sign; energy and force right.
"""Hyper-dual energy engine for one mjed-verify kit case: python ENGINE INPUT_DIR OUTPUT_DIR.

Only the strain energy of each cell, V0 W(F), is written by hand. It is evaluated in
hyper-dual numbers a + b e1 + c e2 + d e1 e2 (e1^2 = e2^2 = 0, e1 e2 != 0; Fike and Alonso),
vectorised over the cells. Seeding the 12 element coordinates x_e gives the element gradient
dE/dx_e in the e1 parts (12 seeds, e2 = 0), hence the element force f_e = -dE/dx_e; seeding
the 78 pairs (i <= j) gives the element Hessian d2E/dx_i dx_j in the e1 e2 parts, hence the
element stiffness K_e (symmetric fill). Element matrices are assembled to the node-major
degrees of freedom 3 a + c.
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "csr"  # "dense", "coo" or "csr"
WRITE_ENERGY = True


class HyperDual:
    """a + b e1 + c e2 + d e1 e2, each part an array broadcast over (cells, seeds)."""

    __slots__ = ("a", "b", "c", "d")
    __array_ufunc__ = None  # ndarray (op) HyperDual defers to the reflected operators below

    def __init__(self, a, b, c, d):
        self.a, self.b, self.c, self.d = a, b, c, d

    def __add__(self, o):
        if isinstance(o, HyperDual):
            return HyperDual(self.a + o.a, self.b + o.b, self.c + o.c, self.d + o.d)
        return HyperDual(self.a + o, self.b, self.c, self.d)

    __radd__ = __add__

    def __neg__(self):
        return HyperDual(-self.a, -self.b, -self.c, -self.d)

    def __sub__(self, o):
        return self + (-o)

    def __rsub__(self, o):
        return (-self) + o

    def __mul__(self, o):
        if isinstance(o, HyperDual):
            return HyperDual(
                self.a * o.a,
                self.a * o.b + self.b * o.a,
                self.a * o.c + self.c * o.a,
                self.a * o.d + self.b * o.c + self.c * o.b + self.d * o.a,
            )
        return HyperDual(self.a * o, self.b * o, self.c * o, self.d * o)

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, HyperDual):
            return self * o.reciprocal()
        return self * (1.0 / o)

    def __rtruediv__(self, o):
        return self.reciprocal() * o

    def chain(self, f0, f1, f2):
        """g(self) from g, g' and g'' at the real part."""
        return HyperDual(f0, f1 * self.b, f1 * self.c, f1 * self.d + f2 * self.b * self.c)

    def reciprocal(self):
        r = 1.0 / self.a
        return self.chain(r, -r * r, 2.0 * r * r * r)

    def __pow__(self, p):
        if p == 2:
            return self * self
        a = self.a
        return self.chain(a**p, p * a ** (p - 1.0), p * (p - 1.0) * a ** (p - 2.0))


def exp(x):
    e = np.exp(x.a)
    return x.chain(e, e, e)


def log(x):
    r = 1.0 / x.a
    return x.chain(np.log(x.a), r, r * r)


def det3(M):
    """Determinant of a 3x3 nested list (hyper-dual numbers or arrays), by cofactors."""
    return (
        M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1])
        - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0])
        + M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])
    )


def inverse3(M):
    """Inverse of a 3x3 nested list by its cofactors: inv[i][j] = cof[j][i] / det."""
    cof = [
        [
            M[(i + 1) % 3][(j + 1) % 3] * M[(i + 2) % 3][(j + 2) % 3]
            - M[(i + 1) % 3][(j + 2) % 3] * M[(i + 2) % 3][(j + 1) % 3]
            for j in range(3)
        ]
        for i in range(3)
    ]
    det = M[0][0] * cof[0][0] + M[0][1] * cof[0][1] + M[0][2] * cof[0][2]
    return [[cof[j][i] / det for j in range(3)] for i in range(3)]


def parts(M, name, shape):
    """One part of a symmetric 3x3 hyper-dual matrix as an array (m, P, 3, 3)."""
    return np.stack(
        [
            np.stack([np.broadcast_to(getattr(M[i][j], name), shape) for j in range(3)], -1)
            for i in range(3)
        ],
        -2,
    )


def eigenvalue_power_sum(C, p):
    """sum_i lambda_i^p over the eigenvalues lambda_i of the symmetric hyper-dual matrix C.

    Real part from eigh; e1, e2 parts tr(f'(C0) C1); e1 e2 part tr(f'(C0) C12) plus the
    Daleckii-Krein term sum_ij f'[lambda_i, lambda_j] (Q^T C1 Q)_ij (Q^T C2 Q)_ji, with the
    divided difference of f'(l) = p l^(p-1) through expm1/log1p (exact for close eigenvalues).
    """
    shape = np.broadcast_shapes(*(np.shape(C[i][j].b) for i in range(3) for j in range(3)))
    shape = np.broadcast_shapes(shape, np.shape(C[0][0].a))
    lam, Q = np.linalg.eigh(parts(C, "a", shape)[:, 0])
    f = lam**p
    g = p * lam ** (p - 1.0)
    li, lj = lam[:, :, None], lam[:, None, :]
    gap = li - lj
    same = gap == 0.0
    safe = np.where(same, 1.0, gap)
    ratio = np.log1p(gap / lj)
    G = np.where(
        same,
        p * (p - 1.0) * lj ** (p - 2.0),
        p * lj ** (p - 1.0) * np.expm1((p - 1.0) * ratio) / safe,
    )
    rot = lambda name: np.einsum("mki,mpkl,mlj->mpij", Q, parts(C, name, shape), Q)
    C1, C2, C12 = rot("b"), rot("c"), rot("d")
    return HyperDual(
        f.sum(axis=1)[:, None],
        np.einsum("mi,mpii->mp", g, C1),
        np.einsum("mi,mpii->mp", g, C2),
        np.einsum("mi,mpii->mp", g, C12) + np.einsum("mij,mpij,mpji->mp", G, C1, C2),
    )


# ---------------------------------------------------------------------------------------------
# kinematics and the ten strain energies (per unit rest volume)


def kinematics(xs, D, frame):
    """F = sum_a x_a (x) D_a and what the energies use; xs the 12 hyper-dual coordinates."""
    F = [[sum(xs[3 * a + k] * D[:, a, i] for a in range(4)) for i in range(3)] for k in range(3)]
    C = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            C[i][j] = C[j][i] = sum(F[k][i] * F[k][j] for k in range(3))
    J = det3(F)
    I1 = C[0][0] + C[1][1] + C[2][2]
    trC2 = sum(C[i][j] * C[j][i] for i in range(3) for j in range(3))
    I2 = 0.5 * (I1 * I1 - trC2)
    E = [[0.5 * (C[i][j] - (1.0 if i == j else 0.0)) for j in range(3)] for i in range(3)]
    return {"F": F, "C": C, "E": E, "J": J, "lnJ": log(J), "I1": I1, "I2": I2, "frame": frame}


def isochoric(k):
    return k["J"] ** (-2.0 / 3.0) * k["I1"], k["J"] ** (-4.0 / 3.0) * k["I2"]


def st_venant_kirchhoff(p, k):
    E = k["E"]
    trE = E[0][0] + E[1][1] + E[2][2]
    trE2 = sum(E[i][j] * E[i][j] for i in range(3) for j in range(3))
    return 0.5 * p["lam"] * trE**2 + p["mu"] * trE2


def neo_hookean(p, k):
    lnJ = k["lnJ"]
    return 0.5 * p["mu"] * (k["I1"] - 3.0) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ**2


def mooney_rivlin(p, k):
    I1b, I2b = isochoric(k)
    return p["c1"] * (I1b - 3.0) + p["c2"] * (I2b - 3.0) + 0.5 * p["k0"] * k["lnJ"] ** 2


def veronda_westmann(p, k):
    I1b, I2b = isochoric(k)
    c1, c2 = p["c1"], p["c2"]
    return (
        c1 * (exp(c2 * (I1b - 3.0)) - 1.0)
        - 0.5 * c1 * c2 * (I2b - 3.0)
        + 0.5 * p["k0"] * k["lnJ"] ** 2
    )


ARRUDA_BOYCE_C = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)


def arruda_boyce(p, k):
    I1b, _ = isochoric(k)
    N = p["N"]
    series = sum(
        c * N ** (1 - i) * (I1b**i - 3.0**i) for i, c in enumerate(ARRUDA_BOYCE_C, start=1)
    )
    return p["mu"] * series + 0.5 * p["k0"] * k["lnJ"] ** 2


def costa(p, k):
    R, E, J = k["frame"], k["E"], k["J"]
    B = [
        [p["b_ff"], p["b_fs"], p["b_fn"]],
        [p["b_fs"], p["b_ss"], p["b_sn"]],
        [p["b_fn"], p["b_sn"], p["b_nn"]],
    ]
    RtE = [[sum(R[:, l, i, None] * E[l][j] for l in range(3)) for j in range(3)] for i in range(3)]
    Ef = [[sum(RtE[i][l] * R[:, l, j, None] for l in range(3)) for j in range(3)] for i in range(3)]
    Q = sum(B[i][j] * Ef[i][j] ** 2 for i in range(3) for j in range(3))
    fibre = 0.5 * p["a"] * (exp(J ** (-4.0 / 3.0) * Q) - 1.0)
    return fibre + p["k0"] * (J * k["lnJ"] - J + 1.0)


def ogden(p, k):
    mu, alpha = p["mu"], p["alpha"]
    stretch_sum = eigenvalue_power_sum(k["C"], 0.5 * alpha)
    iso = mu / alpha**2 * (k["J"] ** (-alpha / 3.0) * stretch_sum - 3.0)
    return iso + 0.5 * p["k0"] * k["lnJ"] ** 2


def yeoh(p, k):
    I1b, _ = isochoric(k)
    s = I1b - 3.0
    return p["c10"] * s + p["c20"] * s**2 + p["c30"] * s**3 + 0.5 * p["k0"] * k["lnJ"] ** 2


def gent(p, k):
    I1b, _ = isochoric(k)
    mu, Jm = p["mu"], p["Jm"]
    return -0.5 * mu * Jm * log(1.0 - (I1b - 3.0) / Jm) + 0.5 * p["k0"] * k["lnJ"] ** 2


def demiray(p, k):
    I1b, _ = isochoric(k)
    a, b = p["a"], p["b"]
    return a / (2.0 * b) * (exp(b * (I1b - 3.0)) - 1.0) + 0.5 * p["k0"] * k["lnJ"] ** 2


MATERIALS = {
    "StVenantKirchhoff": st_venant_kirchhoff,
    "NeoHookean": neo_hookean,
    "MooneyRivlin": mooney_rivlin,
    "VerondaWestmann": veronda_westmann,
    "ArrudaBoyce": arruda_boyce,
    "Costa": costa,
    "Ogden": ogden,
    "Yeoh": yeoh,
    "Gent": gent,
    "Demiray": demiray,
}


# ---------------------------------------------------------------------------------------------
# the element loop, vectorised over the cells


def rest_geometry(X, cells):
    """Shape-function gradients D (m, 4, 3) and rest volumes V0 (m,)."""
    Xe = X[cells]
    Dm = [[Xe[:, j + 1, i] - Xe[:, 0, i] for j in range(3)] for i in range(3)]
    V0 = det3(Dm) / 6.0
    inv = inverse3(Dm)
    D = np.empty((len(cells), 4, 3), dtype=REAL)
    for a in range(3):
        for i in range(3):
            D[:, a + 1, i] = inv[a][i]
    D[:, 0] = -(D[:, 1] + D[:, 2] + D[:, 3])
    return D, V0


def cell_energies(xe, D, V0, frame, law, params, first, second):
    """V0 W at the 12 element coordinates xe (m, 12), seeded for the index lists first (e1)
    and second (e2, or None for a gradient pass).
    """
    P = len(first)
    eye = np.eye(12, dtype=REAL)
    zero = np.zeros((1, P), dtype=REAL)
    xs = [
        HyperDual(
            xe[:, q, None],
            eye[q, first][None, :],
            zero if second is None else eye[q, second][None, :],
            zero,
        )
        for q in range(12)
    ]
    k = kinematics(xs, D[..., None], frame)
    return law(params, k) * V0[:, None]


def element_derivatives(xe, D, V0, frame, law, params):
    """Cell energies (m,), element gradients (m, 12) and element Hessians (m, 12, 12)."""
    m = len(xe)
    every = np.arange(12)
    g = cell_energies(xe, D, V0, frame, law, params, every, None)
    energy = g.a[:, 0]
    grad = np.broadcast_to(g.b, (m, 12))
    iu, ju = np.triu_indices(12)
    h = cell_energies(xe, D, V0, frame, law, params, iu, ju)
    pairs = np.broadcast_to(h.d, (m, len(iu)))
    hess = np.empty((m, 12, 12), dtype=REAL)
    hess[:, iu, ju] = pairs
    hess[:, ju, iu] = pairs
    return energy, grad, hess


def assemble(n, cells, grad, hess):
    """Node-major force -dE/dx (3n,) and the element triplets (rows, cols, values)."""
    m = len(cells)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    force = np.zeros(3 * n, dtype=REAL)
    np.add.at(force, dofs, -grad)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    return force, rows, cols, hess.reshape(m, 144).ravel()


def read_case(folder):
    case = json.loads((folder / "case.json").read_text())
    arrays = {}
    for name, spec in case["arrays"].items():
        raw = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = raw.reshape(spec["shape"])
    return case, arrays


def write_outputs(out, n, force, rows, cols, values, energy):
    out.mkdir(parents=True, exist_ok=True)
    ext, code = (".f64", "<f8") if REAL == np.float64 else (".f32", "<f4")
    force.astype(code).tofile(out / ("force" + ext))
    N = 3 * n
    if LAYOUT == "coo":
        rows.astype("<i8").tofile(out / "stiffness_rows.i64")
        cols.astype("<i8").tofile(out / "stiffness_cols.i64")
        values.astype(code).tofile(out / ("stiffness_values" + ext))
    elif LAYOUT == "csr":
        K = sp.csr_matrix((values, (rows, cols)), shape=(N, N))
        K.sum_duplicates()
        K.sort_indices()
        K.indptr.astype("<i8").tofile(out / "stiffness_indptr.i64")
        K.indices.astype("<i8").tofile(out / "stiffness_indices.i64")
        K.data.astype(code).tofile(out / ("stiffness_values" + ext))
    else:
        K = np.zeros((N, N), dtype=REAL)
        np.add.at(K, (rows, cols), values)
        K.astype(code).tofile(out / ("stiffness" + ext))
    if WRITE_ENERGY:
        np.array([energy], dtype=REAL).astype(code).tofile(out / ("energy" + ext))


def main(argv):
    if len(argv) != 3:
        sys.exit("usage: python ENGINE INPUT_DIR OUTPUT_DIR")
    inp, out = Path(argv[1]), Path(argv[2])
    case, arrays = read_case(inp)
    model = case["model"]
    if model["kind"] != "material" or model["name"] not in MATERIALS:
        sys.exit(f"unsupported model {model.get('name')!r}")
    law = MATERIALS[model["name"]]
    params = {name: REAL(value) for name, value in model["parameters"].items()}
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    n, m = len(X), len(cells)
    frame = None
    if "frame" in arrays:
        frame = np.broadcast_to(arrays["frame"].astype(REAL), (m, 3, 3))
    D, V0 = rest_geometry(X, cells)
    xe = x[cells].reshape(m, 12)
    energies, grad, hess = element_derivatives(xe, D, V0, frame, law, params)
    force, rows, cols, values = assemble(n, cells, grad, hess)
    write_outputs(out, n, force, rows, cols, values, energies.sum())


if __name__ == "__main__":
    main(sys.argv)
