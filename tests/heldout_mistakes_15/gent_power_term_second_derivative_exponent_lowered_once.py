#!/usr/bin/env python3
# MISTAKE: f''(J) of the power terms c J^q written c q (q - 1) J^(q - 1) (the exponent lowered
# once) where c q (q - 1) J^(q - 2) belongs, in the J^(-2/3) I1 term inside Gent's logarithm: f
# and f' right, stiffness wrong wherever J != 1 (both states); force and energy right.
"""P1 tetrahedral hyperelastic engine in the MJED form (Marchesseau et al., MICCAI 2010).

Vectorised over the m cells with NumPy (no Python loop over cells). Precomputed at rest, per
tetrahedron: the shape vectors D_a (gradients of the P1 shape functions: rows of the inverse
of the rest edge matrix [X1 - X0, X2 - X0, X3 - X0], D_0 = -(D_1 + D_2 + D_3)) and the rest
volume V0 = det / 6. Each material is declared as a table of MJED terms W = sum_k f_k(J) g_k(C)
(f with f', f''; g with S_k = 2 dg_k/dC and dS_k/dC : H written as the paper's pieces
beta A H A and beta (H : A) A, or a Hadamard product in a basis for Ogden's eigenvalues and
Costa's fibre frame), and non-separable energies as an outer function of such a sum (Gent's
logarithm, the exponentials of Veronda-Westmann, Demiray and Costa). Node gradient of a term:
V0 (f' g dJ/dx_a + f F S D_a); stiffness by node pairs (4 vertex and 6 edge blocks per cell):
V0 (f'' g dJ_a (x) dJ_b + f' (dJ_a (x) F S D_b + F S D_a (x) dJ_b) + f' g d2J/dx_a dx_b
+ f (D_a . S D_b) Id + f (material block of dS/dC)); each edge block mirrored (transposed) to
(b, a) when assembled into a dense, COO or CSR stiffness; energy sum V0 W.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one exported mjed-verify kit case).
"""

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "csr"
WRITE_ENERGY = True
AB_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)
# node pairs of a tetrahedron: the 4 vertices (self-edges), then the 6 edges (a < b)
PA = np.array([0, 1, 2, 3, 0, 0, 0, 1, 1, 2])
PB = np.array([0, 1, 2, 3, 1, 2, 3, 2, 3, 3])
N_VERTEX = 4


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


# ------------------------------------------------------------------ precomputation at rest
def shape_vectors(points, cells):
    X = points[cells]
    Dm = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
    V0 = np.linalg.det(Dm) / 6.0
    inv = np.linalg.inv(Dm)
    D = np.empty((len(cells), 4, 3), dtype=REAL)
    D[:, 1:] = inv
    D[:, 0] = -inv.sum(axis=1)
    return D, V0


# ------------------------------------------------------------------ f(J) tables
def f_table(J, pieces):
    """Sum of the pieces of f: value, f', f''."""
    f = np.zeros_like(J)
    f1 = np.zeros_like(J)
    f2 = np.zeros_like(J)
    L = np.log(J)
    for kind, c, q in pieces:
        if kind == "pow":  # c J^q
            f = f + c * J**q
            f1 = f1 + c * q * J ** (q - 1.0)
            f2 = f2 + c * q * (q - 1.0) * J ** (q - 1.0)
        elif kind == "ln":  # c ln J
            f = f + c * L
            f1 = f1 + c / J
            f2 = f2 - c / J**2
        elif kind == "ln2":  # c/2 (ln J)^2
            f = f + c / 2.0 * L**2
            f1 = f1 + c * L / J
            f2 = f2 + c * (1.0 - L) / J**2
        elif kind == "jlnj":  # c (J ln J - J + 1)
            f = f + c * (J * L - J + 1.0)
            f1 = f1 + c * L
            f2 = f2 + c / J
    return f, f1, f2


# ------------------------------------------------------------------ g(C) tables
def power_quotients(c, p):
    """Divided differences of lambda^p between the eigenvalues c (m, 3), diagonal p c^(p-1)."""
    ci = c[:, :, None]
    cj = c[:, None, :]
    r = np.log(ci / cj)
    small = np.abs(r) < 1e-6
    rs = np.where(small, 1.0, r)
    general = cj ** (p - 1.0) * np.expm1(p * rs) / np.expm1(rs)
    series = (
        p
        * cj ** (p - 1.0)
        * (1.0 + (p - 1.0) * r / 2.0 + (p - 1.0) * (2.0 * p - 1.0) * r**2 / 12.0)
    )
    return np.where(small, series, general)


def g_table(kin, spec):
    """g, S = 2 dg/dC and the pieces of dS/dC : H."""
    C, I1, eye = kin["C"], kin["I1"], kin["eye"]
    m = len(C)
    kind = spec[0]
    if kind == "one":
        return np.ones(m, dtype=REAL), np.zeros_like(C), []
    if kind == "I1":  # I1^p
        p = spec[1]
        g = I1**p
        S = (2.0 * p * I1 ** (p - 1.0))[:, None, None] * eye
        beta = 2.0 * p * (p - 1.0) * I1 ** (p - 2.0)
        return g, S, [("haa", beta, eye)]
    if kind == "I2":
        g = kin["I2"]
        S = 2.0 * (I1[:, None, None] * eye - C)
        two = np.full(m, 2.0, dtype=REAL)
        return g, S, [("haa", two, eye), ("aha", -two, eye)]
    if kind == "ogden":  # tr C^(alpha/2)
        alpha = spec[1]
        c, N = np.linalg.eigh(C)
        p = alpha / 2.0 - 1.0
        g = (c ** (alpha / 2.0)).sum(axis=1)
        S = alpha * np.einsum("mij,mj,mkj->mik", N, c**p, N)
        Gamma = power_quotients(c, p)
        return g, S, [("had", np.full(m, alpha, dtype=REAL), N, Gamma)]
    if kind == "costa":  # Q = sum B_ij Ef_ij^2, Ef = R^T E R
        R, B = kin["frame"], spec[1]
        E = (C - eye) / 2.0
        Ef = np.einsum("mki,mkl,mlj->mij", R, E, R)
        g = (B * Ef**2).sum(axis=(1, 2))
        S = 2.0 * np.einsum("mik,mkl,mjl->mij", R, B * Ef, R)
        Gamma = np.broadcast_to(B, (m, 3, 3))
        return g, S, [("had", np.ones(m, dtype=REAL), R, Gamma)]
    raise ValueError(kind)


# ------------------------------------------------------------------ MJED term
def material_blocks(kin, pieces):
    """(dS/dC : H_bk) contracted with F and D_a, for the 10 node pairs: (m, 10, 3, 3)."""
    F, D = kin["F"], kin["D"]
    M = np.zeros((len(F), len(PA), 3, 3), dtype=REAL)
    for piece in pieces:
        kind, beta = piece[0], piece[1]
        if kind in ("aha", "haa"):
            A = piece[2]
            FAD = np.einsum("mij,mjk,mak->mai", F, A, D)
            if kind == "aha":
                FAFt = np.einsum("mij,mjk,mlk->mil", F, A, F)
                DAD = np.einsum("mpi,mij,mpj->mp", D[:, PB], A, D[:, PA])
                blk = FAD[:, PB][..., :, None] * FAD[:, PA][..., None, :]
                blk = blk + FAFt[:, None] * DAD[..., None, None]
            else:
                blk = 2.0 * FAD[:, PA][..., :, None] * FAD[:, PB][..., None, :]
        else:  # Hadamard product in the basis N: beta N (Gamma o (N^T H N)) N^T
            N, Gamma = piece[2], piece[3]
            Fn = np.einsum("mij,mjk->mik", F, N)
            d = np.einsum("mji,maj->mai", N, D)
            U = Fn[:, None] * d[:, PB][:, :, None, :]
            V = Fn[:, None] * d[:, PA][:, :, None, :]
            blk = np.einsum("mnip,mpq,mnkq->mnik", U, Gamma, V)
            w = np.einsum("mpq,mnq->mnp", Gamma, d[:, PB] * d[:, PA])
            blk = blk + np.einsum("mip,mnp,mkp->mnik", Fn, w, Fn)
        M = M + beta[:, None, None, None] * blk
    return M


def term(kin, fpieces, gspec):
    """Density, node gradients (m, 4, 3) and pair blocks (m, 10, 3, 3) of f(J) g(C)."""
    J, F, D, dJ = kin["J"], kin["F"], kin["D"], kin["dJ"]
    f, f1, f2 = f_table(J, fpieces)
    g, S, pieces = g_table(kin, gspec)
    FSD = np.einsum("mij,mjk,mak->mai", F, S, D)
    w = f * g
    grad = (f1 * g)[:, None, None] * dJ + f[:, None, None] * FSD
    dJa, dJb = dJ[:, PA], dJ[:, PB]
    Pa, Pb = FSD[:, PA], FSD[:, PB]
    blocks = (f2 * g)[:, None, None, None] * (dJa[..., :, None] * dJb[..., None, :])
    blocks = blocks + f1[:, None, None, None] * (
        dJa[..., :, None] * Pb[..., None, :] + Pa[..., :, None] * dJb[..., None, :]
    )
    blocks = blocks + (f1 * g)[:, None, None, None] * kin["d2J"]
    DSD = np.einsum("mpi,mij,mpj->mp", D[:, PA], S, D[:, PB])
    blocks = blocks + (f[:, None] * DSD)[..., None, None] * np.eye(3, dtype=REAL)
    blocks = blocks + f[:, None, None, None] * material_blocks(kin, pieces)
    return w, grad, blocks


def outer(name, s, prm):
    """Outer function of a non-separable energy: value, first and second derivative."""
    if name == "gent":
        mu, Jm = prm
        t = 1.0 - s / Jm
        return -mu * Jm / 2.0 * np.log(t), mu / 2.0 / t, mu / (2.0 * Jm) / t**2
    if name == "exp":  # c (exp(b s) - 1)
        c, b = prm
        e = np.exp(b * s)
        return c * (e - 1.0), c * b * e, c * b * b * e
    raise ValueError(name)


def declare(name, p):
    """MJED term tables: ('term', f pieces, g spec) or ('outer', name, params, inner terms)."""
    one = ("one",)
    iso1 = [("term", [("pow", 1.0, -2.0 / 3.0)], ("I1", 1.0)), ("term", [("pow", -3.0, 0.0)], one)]
    if name == "NeoHookean":
        mu, lam = p["mu"], p["lam"]
        return [
            ("term", [("pow", mu / 2.0, 0.0)], ("I1", 1.0)),
            ("term", [("pow", -1.5 * mu, 0.0), ("ln", -mu, 0.0), ("ln2", lam, 0.0)], one),
        ]
    if name == "MooneyRivlin":
        c1, c2, k0 = p["c1"], p["c2"], p["k0"]
        return [
            ("term", [("pow", c1, -2.0 / 3.0)], ("I1", 1.0)),
            ("term", [("pow", c2, -4.0 / 3.0)], ("I2",)),
            ("term", [("pow", -3.0 * c1 - 3.0 * c2, 0.0), ("ln2", k0, 0.0)], one),
        ]
    if name == "Yeoh":
        c10, c20, c30, k0 = p["c10"], p["c20"], p["c30"], p["k0"]
        a1 = c10 - 6.0 * c20 + 27.0 * c30
        a2 = c20 - 9.0 * c30
        a0 = -3.0 * c10 + 9.0 * c20 - 27.0 * c30
        return [
            ("term", [("pow", a1, -2.0 / 3.0)], ("I1", 1.0)),
            ("term", [("pow", a2, -4.0 / 3.0)], ("I1", 2.0)),
            ("term", [("pow", c30, -2.0)], ("I1", 3.0)),
            ("term", [("pow", a0, 0.0), ("ln2", k0, 0.0)], one),
        ]
    if name == "ArrudaBoyce":
        mu, k0, n = p["mu"], p["k0"], p["N"]
        terms, a0 = [], 0.0
        for i, ci in enumerate(AB_C, start=1):
            coef = mu * ci * n ** (1.0 - i)
            terms.append(("term", [("pow", coef, -2.0 * i / 3.0)], ("I1", float(i))))
            a0 = a0 - coef * 3.0**i
        terms.append(("term", [("pow", a0, 0.0), ("ln2", k0, 0.0)], one))
        return terms
    if name == "Gent":
        return [
            ("outer", "gent", (p["mu"], p["Jm"]), iso1),
            ("term", [("ln2", p["k0"], 0.0)], one),
        ]
    if name == "VerondaWestmann":
        c1, c2, k0 = p["c1"], p["c2"], p["k0"]
        return [
            ("outer", "exp", (c1, c2), iso1),
            ("term", [("pow", -c1 * c2 / 2.0, -4.0 / 3.0)], ("I2",)),
            ("term", [("pow", 1.5 * c1 * c2, 0.0), ("ln2", k0, 0.0)], one),
        ]
    if name == "Demiray":
        a, b = p["a"], p["b"]
        return [
            ("outer", "exp", (a / (2.0 * b), b), iso1),
            ("term", [("ln2", p["k0"], 0.0)], one),
        ]
    if name == "Ogden":
        mu, alpha, k0 = p["mu"], p["alpha"], p["k0"]
        return [
            ("term", [("pow", mu / alpha**2, -alpha / 3.0)], ("ogden", alpha)),
            ("term", [("pow", -3.0 * mu / alpha**2, 0.0), ("ln2", k0, 0.0)], one),
        ]
    if name == "StVenantKirchhoff":
        mu, lam = p["mu"], p["lam"]
        return [
            ("term", [("pow", lam / 8.0 + mu / 4.0, 0.0)], ("I1", 2.0)),
            ("term", [("pow", -(0.75 * lam + 0.5 * mu), 0.0)], ("I1", 1.0)),
            ("term", [("pow", -mu / 2.0, 0.0)], ("I2",)),
            ("term", [("pow", 1.125 * lam + 0.75 * mu, 0.0)], one),
        ]
    if name == "Costa":
        B = np.array(
            [
                [p["b_ff"], p["b_fs"], p["b_fn"]],
                [p["b_fs"], p["b_ss"], p["b_sn"]],
                [p["b_fn"], p["b_sn"], p["b_nn"]],
            ],
            dtype=REAL,
        )
        return [
            (
                "outer",
                "exp",
                (p["a"] / 2.0, 1.0),
                [("term", [("pow", 1.0, -4.0 / 3.0)], ("costa", B))],
            ),
            ("term", [("jlnj", p["k0"], 0.0)], one),
        ]
    raise ValueError(f"unknown material {name}")


# ------------------------------------------------------------------ kinematics
def kinematics(x, cells, D, frame):
    xc = x[cells]
    F = np.einsum("mak,mai->mki", xc, D)
    J = np.linalg.det(F)
    Finv = np.linalg.inv(F)
    FiTD = np.einsum("mji,maj->mai", Finv, D)
    dJ = J[:, None, None] * FiTD
    a, b = FiTD[:, PA], FiTD[:, PB]
    d2J = J[:, None, None, None] * (
        a[..., :, None] * b[..., None, :] - b[..., :, None] * a[..., None, :]
    )
    C = np.einsum("mki,mkj->mij", F, F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = (I1**2 - np.einsum("mij,mji->m", C, C)) / 2.0
    eye = np.broadcast_to(np.eye(3, dtype=REAL), C.shape)
    return dict(F=F, J=J, dJ=dJ, d2J=d2J, C=C, I1=I1, I2=I2, D=D, eye=eye, frame=frame)


def evaluate(kin, table):
    m = len(kin["J"])
    W = np.zeros(m, dtype=REAL)
    grad = np.zeros((m, 4, 3), dtype=REAL)
    blocks = np.zeros((m, len(PA), 3, 3), dtype=REAL)
    for item in table:
        if item[0] == "term":
            w, g, b = term(kin, item[1], item[2])
        else:
            _, name, prm, inner = item
            s = np.zeros(m, dtype=REAL)
            gs = np.zeros((m, 4, 3), dtype=REAL)
            bs = np.zeros((m, len(PA), 3, 3), dtype=REAL)
            for it in inner:
                ws, gi, bi = term(kin, it[1], it[2])
                s, gs, bs = s + ws, gs + gi, bs + bi
            phi, phi1, phi2 = outer(name, s, prm)
            w = phi
            g = phi1[:, None, None] * gs
            b = phi2[:, None, None, None] * (gs[:, PA][..., :, None] * gs[:, PB][..., None, :])
            b = b + phi1[:, None, None, None] * bs
        W, grad, blocks = W + w, grad + g, blocks + b
    return W, grad, blocks


# ------------------------------------------------------------------ assembly
def assemble(cells, n, V0, grad, blocks):
    force = np.zeros((n, 3), dtype=REAL)
    np.add.at(force, cells, -V0[:, None, None] * grad)
    K = V0[:, None, None, None] * blocks
    dof = 3 * cells[:, :, None] + np.arange(3)
    ra, rb = dof[:, PA], dof[:, PB]
    rows = np.broadcast_to(ra[..., :, None], K.shape)
    cols = np.broadcast_to(rb[..., None, :], K.shape)
    # the edge blocks mirrored: K_ba = K_ab^T
    e = slice(N_VERTEX, None)
    mrows = np.broadcast_to(rb[:, e][..., :, None], K[:, e].shape)
    mcols = np.broadcast_to(ra[:, e][..., None, :], K[:, e].shape)
    mvals = np.swapaxes(K[:, e], -1, -2)
    rows = np.concatenate([rows.ravel(), mrows.ravel()])
    cols = np.concatenate([cols.ravel(), mcols.ravel()])
    vals = np.concatenate([K.ravel(), mvals.ravel()])
    return force.ravel(), rows, cols, vals


def write_outputs(out, n, force, rows, cols, vals, energy):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    single = REAL == np.float32
    ext = ".f32" if single else ".f64"
    fmt = "<f4" if single else "<f8"
    force.astype(fmt).tofile(out / f"force{ext}")
    if LAYOUT == "coo":
        rows.astype("<i8").tofile(out / "stiffness_rows.i64")
        cols.astype("<i8").tofile(out / "stiffness_cols.i64")
        vals.astype(fmt).tofile(out / f"stiffness_values{ext}")
    else:
        K = sp.coo_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n)).tocsr()
        K.sum_duplicates()
        if LAYOUT == "csr":
            K.indptr.astype("<i8").tofile(out / "stiffness_indptr.i64")
            K.indices.astype("<i8").tofile(out / "stiffness_indices.i64")
            K.data.astype(fmt).tofile(out / f"stiffness_values{ext}")
        else:
            K.toarray().astype(fmt).tofile(out / f"stiffness{ext}")
    if WRITE_ENERGY:
        np.array([energy]).astype(fmt).tofile(out / f"energy{ext}")


def main(argv):
    case, arrays = read_case(argv[1])
    model = case["model"]
    points = arrays["points"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    x = arrays["positions"].astype(REAL)
    frame = arrays["frame"].astype(REAL) if "frame" in arrays else None
    n = len(points)
    D, V0 = shape_vectors(points, cells)
    table = declare(model["name"], parameters(model))
    kin = kinematics(x, cells, D, frame)
    W, grad, blocks = evaluate(kin, table)
    force, rows, cols, vals = assemble(cells, n, V0, grad, blocks)
    energy = (V0 * W).sum()
    write_outputs(argv[2], n, force, rows, cols, vals, energy)


if __name__ == "__main__":
    main(sys.argv)
