#!/usr/bin/env python3
# MooneyRivlin: f''(J) of k0/2 (ln J)^2 by a forward difference of f'(J), step 1e-6
"""A Multiplicative Jacobian Energy Decomposition (MJED) engine for P1 tetrahedra, in NumPy.

Written the paper's way (Marchesseau et al., MICCAI 2010): per tetrahedron the strain energy
is a sum of terms f(J) g(C) (and of functions of such sums: exponentials, logarithms, powers),
the force from the per-term derivatives (eq. 3)

    dW/dQ_i = f'(J) g dJ/dQ_i + f(J) F S D_i,        S = 2 dg/dC,  dJ/dQ_i = J F^-T D_i,

and the stiffness from the per-edge 3x3 blocks K_ij: the J-J block f'' g dJ_i dJ_j^T, the
cross blocks f' (dJ_i (F S D_j)^T + (F S D_i) dJ_j^T), the antisymmetric block
f' g (dJ_i dJ_j^T - dJ_j dJ_i^T) / J, the geometric block f (D_i . S D_j) Id and the material
blocks f F L(i, j) F^T, where dS/dC : H is a sum of beta A H A' and beta (H : A) A terms.

    python ENGINE INPUT_DIR OUTPUT_DIR
"""

import json
import os
import sys

import numpy as np

REAL = np.float64
SUFFIX = ".f64"
OUT = "<f8"

# ----------------------------------------------------------------------------- input


def read_case(folder):
    with open(os.path.join(folder, "case.json")) as fh:
        meta = json.load(fh)
    arrays = {}
    for name, spec in meta["arrays"].items():
        data = np.fromfile(os.path.join(folder, spec["file"]), dtype=spec["dtype"])
        arrays[name] = data.reshape(spec["shape"])
    return meta, arrays


# ----------------------------------------------------------------------------- geometry


def shape_vectors(points, cells):
    """Shape vectors D_a (m, 4, 3) and rest volumes V0 (m,)."""
    P = points[cells]
    M = np.transpose(P[:, 1:, :] - P[:, :1, :], (0, 2, 1))  # columns P1 - P0, P2 - P0, P3 - P0
    V0 = np.linalg.det(M) / 6.0
    Minv = np.linalg.inv(M)
    D = np.empty((len(cells), 4, 3), dtype=points.dtype)
    D[:, 1:, :] = Minv
    D[:, 0, :] = -Minv.sum(axis=1)
    return D, V0


# ----------------------------------------------------------------------------- J functions
# each returns (f, f', f'') of J


def j_power(J, p):
    return J**p, p * J ** (p - 1.0), p * (p - 1.0) * J ** (p - 2.0)


def j_one(J):
    one = np.ones_like(J)
    return one, 0.0 * one, 0.0 * one


def j_log_squared(J, k0):
    """k0/2 (ln J)^2."""
    L = np.log(J)
    h = 1e-6
    return 0.5 * k0 * L * L, k0 * L / J, (k0 * np.log(J + h) / (J + h) - k0 * L / J) / h


def j_neo_hookean(J, mu, lam):
    """-mu ln J + lam/2 (ln J)^2."""
    L = np.log(J)
    return -mu * L + 0.5 * lam * L * L, (-mu + lam * L) / J, (mu + lam * (1.0 - L)) / (J * J)


def j_costa(J, k0):
    """k0 (J ln J - J + 1)."""
    L = np.log(J)
    return k0 * (J * L - J + 1.0), k0 * L, k0 / J


# ----------------------------------------------------------------------------- C functions
# each returns (g, S = 2 dg/dC, forms1, forms2) with
#   dS/dC : H = sum beta A H A2 (forms1: (beta, A, A2)) + sum beta (H : A) A (forms2: (beta, A))


def eye_like(C):
    return np.broadcast_to(np.eye(3, dtype=C.dtype), C.shape)


def g_one(C):
    return np.ones(C.shape[0], dtype=C.dtype), np.zeros_like(C), [], []


def g_i1_power(C, c, n=1):
    I = eye_like(C)
    I1 = np.trace(C, axis1=1, axis2=2)
    g = c * I1**n
    S = (2.0 * c * n * I1 ** (n - 1))[:, None, None] * I
    forms2 = [] if n == 1 else [(2.0 * c * n * (n - 1) * I1 ** (n - 2), I)]
    return g, S, [], forms2


def g_i2(C, c):
    I = eye_like(C)
    I1 = np.trace(C, axis1=1, axis2=2)
    trC2 = np.einsum("mij,mji->m", C, C)
    g = 0.5 * c * (I1 * I1 - trC2)
    S = 2.0 * c * (I1[:, None, None] * I - C)
    beta = np.full(C.shape[0], 2.0 * c, dtype=C.dtype)
    return g, S, [(-beta, I, I)], [(beta, I)]


def g_svk(C, mu, lam):
    """lam/2 (tr E)^2 + mu tr(E^2)."""
    I = eye_like(C)
    E = 0.5 * (C - I)
    trE = np.trace(E, axis1=1, axis2=2)
    g = 0.5 * lam * trE * trE + mu * np.einsum("mij,mji->m", E, E)
    S = lam * trE[:, None, None] * I + 2.0 * mu * E
    one = np.ones(C.shape[0], dtype=C.dtype)
    return g, S, [(mu * one, I, I)], [(0.5 * lam * one, I)]


def g_costa(C, B, R):
    """Q = sum_ij B_ij Ef_ij^2, Ef = R^T E R; dS/dC : H = R (B o (R^T H R)) R^T."""
    I = eye_like(C)
    E = 0.5 * (C - I)
    Ef = np.einsum("mki,mkl,mlj->mij", R, E, R)
    g = np.einsum("ij,mij->m", B, Ef * Ef)
    S = 2.0 * np.einsum("mik,mkl,mjl->mij", R, B * Ef, R)
    s, V = np.linalg.eigh(B)  # B o M = sum_r s_r diag(v_r) M diag(v_r)
    forms1 = []
    one = np.ones(C.shape[0], dtype=C.dtype)
    for r in range(3):
        A = np.einsum("mik,k,mjk->mij", R, V[:, r], R)
        forms1.append((s[r] * one, A, A))
    return g, S, forms1, []


def g_ogden(C, c, p):
    """Ogden: c sum_i lambda_i^p over the eigenvalues of C; divided differences for dS/dC."""
    lam, vec = np.linalg.eigh(C)
    P = np.einsum("mia,mja->maij", vec, vec)  # P[:, a] = n_a n_a^T
    g = c * (lam**p).sum(axis=1)
    phi = c * 2.0 * p * lam ** (p - 1.0)  # S = sum phi_a P_a
    dphi = c * 2.0 * p * (p - 1.0) * lam ** (p - 2.0)
    S = np.einsum("ma,maij->mij", phi, P)
    forms1 = []
    for a in range(3):
        for b in range(3):
            if a == b:
                theta = dphi[:, a]
            else:
                diff = lam[:, a] - lam[:, b]
                close = np.abs(diff) <= 1e-6 * np.abs(lam).max(axis=1)
                mid = 0.5 * (lam[:, a] + lam[:, b])
                safe = np.where(close, 1.0, diff)
                theta = np.where(
                    close,
                    c * 2.0 * p * (p - 1.0) * mid ** (p - 2.0),
                    (phi[:, a] - phi[:, b]) / safe,
                )
            forms1.append((theta, P[:, a], P[:, b]))
    return g, S, forms1, []


# ----------------------------------------------------------------------------- one term


def term_derivatives(F, Finv, J, D, fJ, gC):
    """Value (m,), gradient (m, 4, 3) and Hessian (m, 4, 4, 3, 3) of f(J) g(C) in a cell."""
    f0, f1, f2 = fJ
    g, S, forms1, forms2 = gC
    G = J[:, None, None] * np.einsum("mik,mai->mak", Finv, D)  # dJ/dQ_a = J F^-T D_a
    FSD = np.einsum("mki,mij,maj->mak", F, S, D)  # d g / dQ_a = F S D_a
    value = f0 * g
    grad = (f1 * g)[:, None, None] * G + f0[:, None, None] * FSD

    GG = np.einsum("mak,mbl->mabkl", G, G)
    hess = (f2 * g)[:, None, None, None, None] * GG
    cross = np.einsum("mak,mbl->mabkl", G, FSD) + np.einsum("mak,mbl->mabkl", FSD, G)
    hess += f1[:, None, None, None, None] * cross
    d2J = (GG - np.transpose(GG, (0, 1, 2, 4, 3))) / J[:, None, None, None, None]
    hess += (f1 * g)[:, None, None, None, None] * d2J

    I = np.eye(3, dtype=F.dtype)
    DSD = np.einsum("mai,mij,mbj->mab", D, S, D)
    inner = np.einsum("mab,kl->mabkl", DSD, I)
    for beta, A, A2 in forms1:
        FA = np.einsum("mki,mij->mkj", F, A)
        FAFt = np.einsum("mkj,mlj->mkl", FA, F)
        FAD = np.einsum("mkj,maj->mak", FA, D)
        FA2D = np.einsum("mki,mij,maj->mak", F, A2, D)
        DAD = np.einsum("mbi,mij,maj->mab", D, A2, D)  # D_b . A2 D_a
        half1 = np.einsum("mab,mkl->mabkl", DAD, FAFt)
        half2 = np.einsum("mbk,mal->mabkl", FAD, FA2D)
        inner += beta[:, None, None, None, None] * (half1 + half2)
    for beta, A in forms2:
        FAD = np.einsum("mki,mij,maj->mak", F, A, D)
        inner += (2.0 * beta)[:, None, None, None, None] * np.einsum("mak,mbl->mabkl", FAD, FAD)
    hess += f0[:, None, None, None, None] * inner
    return value, grad, hess


def group(terms, constant=0.0, kind="sum", a=None):
    """A sum h of terms, then phi(h): "sum" (h), "exp" (a exp(h)), "log" (a0 ln(a1 + h)),
    "power" (c (h + s)^n).
    """
    value, grad, hess = terms[0]
    for v, g, h in terms[1:]:
        value, grad, hess = value + v, grad + g, hess + h
    h = value + constant
    if kind == "sum":
        return h, grad, hess
    if kind == "exp":
        e = a * np.exp(h)
        p0, p1, p2 = e, e, e
    elif kind == "log":
        c, s = a
        p0, p1, p2 = c * np.log(s + h), c / (s + h), -c / (s + h) ** 2
    elif kind == "power":
        c, s, n = a
        p0 = c * (h + s) ** n
        p1 = c * n * (h + s) ** (n - 1)
        p2 = c * n * (n - 1) * (h + s) ** (n - 2)
    gg = np.einsum("mak,mbl->mabkl", grad, grad)
    return (
        p0,
        p1[:, None, None] * grad,
        p1[:, None, None, None, None] * hess + p2[:, None, None, None, None] * gg,
    )


# ----------------------------------------------------------------------------- materials

AB_COEFFS = (1.0 / 2.0, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)
B_NAMES = ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")


def groups_of(name, p, F, Finv, J, C, D, frame):
    def T(fJ, gC):
        return term_derivatives(F, Finv, J, D, fJ, gC)

    def vol(fJ):
        return T(fJ, g_one(C))

    if name == "NeoHookean":
        mu, lam = p["mu"], p["lam"]
        return [
            group(
                [T(j_one(J), g_i1_power(C, 0.5 * mu)), vol(j_neo_hookean(J, mu, lam))],
                constant=-1.5 * mu,
            )
        ]
    if name == "StVenantKirchhoff":
        return [group([T(j_one(J), g_svk(C, p["mu"], p["lam"]))])]
    if name == "MooneyRivlin":
        c1, c2 = p["c1"], p["c2"]
        return [
            group(
                [
                    T(j_power(J, -2.0 / 3.0), g_i1_power(C, c1)),
                    T(j_power(J, -4.0 / 3.0), g_i2(C, c2)),
                    vol(j_log_squared(J, p["k0"])),
                ],
                constant=-3.0 * (c1 + c2),
            )
        ]
    if name == "Yeoh":
        c10 = p["c10"]
        out = [
            group(
                [T(j_power(J, -2.0 / 3.0), g_i1_power(C, c10)), vol(j_log_squared(J, p["k0"]))],
                constant=-3.0 * c10,
            )
        ]
        for n, c in ((2, p["c20"]), (3, p["c30"])):
            u = T(j_power(J, -2.0 / 3.0), g_i1_power(C, 1.0))
            out.append(group([u], kind="power", a=(c, -3.0, n)))
        return out
    if name == "ArrudaBoyce":
        mu, N = p["mu"], p.get("N", 8.0)
        coeffs = [mu * ci * N ** (1 - i) for i, ci in enumerate(AB_COEFFS, start=1)]
        terms = [
            T(j_power(J, -2.0 * i / 3.0), g_i1_power(C, ai, i))
            for i, ai in enumerate(coeffs, start=1)
        ]
        terms.append(vol(j_log_squared(J, p["k0"])))
        rest = sum(ai * 3.0**i for i, ai in enumerate(coeffs, start=1))
        return [group(terms, constant=-rest)]
    if name == "Gent":
        mu, Jm = p["mu"], p["Jm"]
        u = T(j_power(J, -2.0 / 3.0), g_i1_power(C, -1.0 / Jm))
        return [
            group([u], kind="log", a=(-0.5 * mu * Jm, 1.0 + 3.0 / Jm)),
            group([vol(j_log_squared(J, p["k0"]))]),
        ]
    if name == "VerondaWestmann":
        c1, c2 = p["c1"], p["c2"]
        u = T(j_power(J, -2.0 / 3.0), g_i1_power(C, c2))
        return [
            group([u], constant=-3.0 * c2, kind="exp", a=c1),
            group(
                [
                    T(j_power(J, -4.0 / 3.0), g_i2(C, -0.5 * c1 * c2)),
                    vol(j_log_squared(J, p["k0"])),
                ],
                constant=1.5 * c1 * c2 - c1,
            ),
        ]
    if name == "Demiray":
        a, b = p["a"], p["b"]
        u = T(j_power(J, -2.0 / 3.0), g_i1_power(C, b))
        return [
            group([u], constant=-3.0 * b, kind="exp", a=a / (2.0 * b)),
            group([vol(j_log_squared(J, p["k0"]))], constant=-a / (2.0 * b)),
        ]
    if name == "Ogden":
        mu, alpha = p["mu"], p["alpha"]
        c = mu / alpha**2
        return [
            group(
                [
                    T(j_power(J, -alpha / 3.0), g_ogden(C, c, 0.5 * alpha)),
                    vol(j_log_squared(J, p["k0"])),
                ],
                constant=-3.0 * c,
            )
        ]
    if name == "Costa":
        b = [p[k] for k in B_NAMES]
        B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]], dtype=C.dtype)
        R = frame
        half_a = 0.5 * p["a"]
        return [
            group([T(j_power(J, -4.0 / 3.0), g_costa(C, B, R))], kind="exp", a=half_a),
            group([vol(j_costa(J, p["k0"]))], constant=-half_a),
        ]
    raise SystemExit(f"material {name} not implemented")


def read_frame(arrays, m):
    R = arrays["frame"].astype(REAL)
    return np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R


# ----------------------------------------------------------------------------- engine


def element_terms(meta, arrays):
    points = arrays["points"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    x = arrays["positions"].astype(REAL)
    model = meta["model"]
    p = {k: REAL(v) for k, v in model["parameters"].items()}
    D, V0 = shape_vectors(points, cells)
    F = np.einsum("mak,mai->mki", x[cells], D)
    J = np.linalg.det(F)
    Finv = np.linalg.inv(F)
    C = np.einsum("mki,mkj->mij", F, F)
    frame = read_frame(arrays, len(cells)) if "frame" in arrays else None
    W = np.zeros(len(cells), dtype=REAL)
    grad = np.zeros((len(cells), 4, 3), dtype=REAL)
    hess = np.zeros((len(cells), 4, 4, 3, 3), dtype=REAL)
    for w, g, h in groups_of(model["name"], p, F, Finv, J, C, D, frame):
        W, grad, hess = W + w, grad + g, hess + h
    fe = -V0[:, None, None] * grad
    Ke = V0[:, None, None, None, None] * hess
    energy = np.sum(V0 * W)
    return cells, fe, Ke, energy


def write_outputs(out, n, cells, fe, Ke, energy):
    os.makedirs(out, exist_ok=True)
    force = np.zeros((n, 3), dtype=REAL)
    np.add.at(force, cells, fe)
    force.astype(OUT).tofile(os.path.join(out, "force" + SUFFIX))
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12)
    blocks = np.transpose(Ke, (0, 1, 3, 2, 4)).reshape(len(cells), 12, 12)
    rows = np.broadcast_to(dofs[:, :, None], blocks.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], blocks.shape).ravel()
    rows.astype("<i8").tofile(os.path.join(out, "stiffness_rows.i64"))
    cols.astype("<i8").tofile(os.path.join(out, "stiffness_cols.i64"))
    blocks.ravel().astype(OUT).tofile(os.path.join(out, "stiffness_values" + SUFFIX))
    np.array([energy]).astype(OUT).tofile(os.path.join(out, "energy" + SUFFIX))


def main(argv):
    if len(argv) != 3:
        raise SystemExit("usage: ENGINE INPUT_DIR OUTPUT_DIR")
    meta, arrays = read_case(argv[1])
    if meta["model"]["kind"] != "material":
        raise SystemExit("only built-in materials")
    cells, fe, Ke, energy = element_terms(meta, arrays)
    write_outputs(argv[2], int(meta["n_nodes"]), cells, fe, Ke, energy)


if __name__ == "__main__":
    main(sys.argv)
