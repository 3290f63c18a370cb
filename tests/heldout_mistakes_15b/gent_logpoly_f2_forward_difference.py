#!/usr/bin/env python3
# MISTAKE: f''(J) of the volumetric k0/2 (ln J)^2 by a forward difference of the analytic f' with
# an absolute step 1e-5 in J ('only the volumetric term needs it'): O(h) truncation, about 1e-5
# relative in the volumetric f'' dJ (x) dJ blocks; energy and force right.
"""P1 tetrahedral hyperelastic engine in the MJED form (multiplicative Jacobian energy
decomposition): W = sum_k f_k(J) g_k(C), with groups c phi(u), u = sum_k f_k(J) g_k(C).

Vectorised over the m cells with NumPy. Per cell: rest shape vectors D_a (gradients of the P1
shape functions, rows of Dm^-1 and D_0 = -(D_1 + D_2 + D_3)) and rest volume V0 = det(Dm) / 6.
At the current state F = sum_a x_a (x) D_a, J = det F, C = F^T F. Per node a:
dJ_a = J F^-T D_a; per pair (a, b): d2J_ab = J (F^-T D_a (x) F^-T D_b - F^-T D_b (x) F^-T D_a).
Each g is given by its value, G = dg/dC and the linear map dC -> dG (its second derivative);
dg_a = 2 F G D_a and d2g_ab = 2 (D_a . G D_b) I + 2 F dG[dC_b] D_a (columns over the direction
of node b). A term's force and stiffness follow from the product rule:
d(fg)_a = f' g dJ_a + f dg_a,
d2(fg)_ab = f'' g dJ_a dJ_b^T + f' (dJ_a dg_b^T + dg_a dJ_b^T) + f' g d2J_ab + f d2g_ab,
and a group adds c (phi'' du_a du_b^T + phi' d2u_ab). Force f_a = -V0 dW_a, stiffness
K_ab = V0 d2W_ab assembled through the node-major dof map (dense, COO or CSR); energy sum V0 W.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (one exported mjed-verify kit case).
"""

import json
import math
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REAL = np.float64
LAYOUT = "coo"
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


# ------------------------------------------------------------------ functions of J: (f, f', f'')


def jpower(q):
    def f(J):
        if q == 0.0:
            one = np.ones_like(J)
            return one, 0.0 * one, 0.0 * one
        return J**q, q * J ** (q - 1.0), q * (q - 1.0) * J ** (q - 2.0)

    return f


def logpoly(a2, a1=0.0, a0=0.0):
    def f(J):
        L = np.log(J)
        h = 1e-5  # forward difference of f' for f''
        d1 = (2.0 * a2 * L + a1) / J
        d1h = (2.0 * a2 * np.log(J + h) + a1) / (J + h)
        return (a2 * L + a1) * L + a0, d1, (d1h - d1) / h

    return f


def jlogj(k, c=0.0):
    def f(J):
        L = np.log(J)
        return k * (J * L - J + 1.0) + c, k * L, k / J

    return f


# ------------------------------------------------------------------ functions of C
# Each returns (g, G, dG) with G = dg/dC (m, 3, 3) and dG(dC) its derivative along dC
# (dC of shape (m, d, 3, 3), d directions).

EYE = np.eye(3)


def trace(A):
    return np.einsum("...ii->...", A)


def unity(C):
    m = len(C)
    return np.ones(m, dtype=REAL), np.zeros((m, 3, 3), dtype=REAL), lambda dC: 0.0 * dC


def i1power(c, n=1):
    def g(C):
        I1 = trace(C)
        G = (c * n * I1 ** (n - 1))[:, None, None] * EYE

        def dG(dC):
            s = c * n * (n - 1) * I1 ** (n - 2) if n > 1 else 0.0 * I1
            return (s[:, None] * trace(dC))[..., None, None] * EYE

        return c * I1**n, G, dG

    return g


def linear_i2(c):
    def g(C):
        I1 = trace(C)
        I2 = 0.5 * (I1**2 - trace(C @ C))
        G = c * (I1[:, None, None] * EYE - C)

        def dG(dC):
            return c * (trace(dC)[..., None, None] * EYE - dC)

        return c * I2, G, dG

    return g


def green_quadratic(mu, lam):
    def g(C):
        E = 0.5 * (C - EYE)
        trE = trace(E)
        G = 0.5 * lam * trE[:, None, None] * EYE + mu * E

        def dG(dC):
            return 0.25 * lam * trace(dC)[..., None, None] * EYE + 0.5 * mu * dC

        return 0.5 * lam * trE**2 + mu * trace(E @ E), G, dG

    return g


def fibre_quadratic(B, R):
    def g(C):
        E = 0.5 * (C - EYE)
        Ef = np.einsum("mIi,mIJ,mJj->mij", R, E, R)
        Q = np.einsum("ij,mij->m", B, Ef**2)
        G = np.einsum("mIi,mij,mJj->mIJ", R, B * Ef, R)

        def dG(dC):
            dEf = 0.5 * np.einsum("mIi,mdIJ,mJj->mdij", R, dC, R)
            return np.einsum("mIi,mdij,mJj->mdIJ", R, B * dEf, R)

        return Q, G, dG

    return g


def eigen_power_sum(c, beta):
    """Ogden's g = c sum_i c_i^beta over the eigenvalues c_i of C."""

    def g(C):
        lam, N = np.linalg.eigh(C)
        h1 = c * beta * lam ** (beta - 1.0)
        h2 = c * beta * (beta - 1.0) * lam ** (beta - 2.0)
        G = np.einsum("mIi,mi,mJi->mIJ", N, h1, N)
        # divided differences of h' between eigenvalues, without cancellation
        L = np.log(lam[:, :, None] / lam[:, None, :])
        same = np.abs(L) < 1e-300
        Ls = np.where(same, 1.0, L)
        ratio = np.where(same, beta - 1.0, np.expm1((beta - 1.0) * Ls) / np.expm1(Ls))
        q = c * beta * lam[:, None, :] ** (beta - 2.0) * ratio
        idx = np.arange(3)
        q[:, idx, idx] = h2

        def dG(dC):
            dCn = np.einsum("mIi,mdIJ,mJj->mdij", N, dC, N)
            return np.einsum("mIi,mdij,mJj->mdIJ", N, q[:, None] * dCn, N)

        return c * np.sum(lam**beta, axis=1), G, dG

    return g


# ------------------------------------------------------------ group functions (phi, phi', phi'')


def phi_exp(u):
    e = np.exp(u)
    return e, e, e


def phi_log(shift):
    def f(u):
        a = shift + u
        return np.log(a), 1.0 / a, -1.0 / a**2

    return f


def phi_power(n, shift):
    def f(u):
        a = shift + u
        return a**n, n * a ** (n - 1.0), n * (n - 1.0) * a ** (n - 2.0)

    return f


# ------------------------------------------------------------------ material term tables
# A table is a list of groups (coefficient, phi or None, [(f of J, g of C), ...]).


def term_table(name, p, R):
    if name == "NeoHookean":
        mu, lam = p["mu"], p["lam"]
        return [
            (
                1.0,
                None,
                [
                    (jpower(0.0), i1power(0.5 * mu)),
                    (logpoly(0.5 * lam, -mu, -1.5 * mu), unity),
                ],
            )
        ]
    if name == "MooneyRivlin":
        c1, c2, k0 = p["c1"], p["c2"], p["k0"]
        return [
            (
                1.0,
                None,
                [
                    (jpower(-2.0 / 3.0), i1power(c1)),
                    (jpower(-4.0 / 3.0), linear_i2(c2)),
                    (logpoly(0.5 * k0, 0.0, -3.0 * (c1 + c2)), unity),
                ],
            )
        ]
    if name == "Yeoh":
        c10, c20, c30, k0 = p["c10"], p["c20"], p["c30"], p["k0"]
        u = [(jpower(-2.0 / 3.0), i1power(1.0))]
        return [
            (
                1.0,
                None,
                [(jpower(-2.0 / 3.0), i1power(c10)), (logpoly(0.5 * k0, 0.0, -3.0 * c10), unity)],
            ),
            (c20, phi_power(2.0, -3.0), u),
            (c30, phi_power(3.0, -3.0), u),
        ]
    if name == "ArrudaBoyce":
        mu, k0, N = p["mu"], p["k0"], p.get("N", 8.0)
        coeffs = [mu * c * N ** (1 - i) for i, c in enumerate(AB_C, start=1)]
        terms = [(jpower(-2.0 * i / 3.0), i1power(a, i)) for i, a in enumerate(coeffs, start=1)]
        rest = sum(a * 3.0**i for i, a in enumerate(coeffs, start=1))
        terms.append((logpoly(0.5 * k0, 0.0, -rest), unity))
        return [(1.0, None, terms)]
    if name == "Gent":
        mu, Jm, k0 = p["mu"], p["Jm"], p["k0"]
        return [
            (-0.5 * mu * Jm, phi_log(1.0 + 3.0 / Jm), [(jpower(-2.0 / 3.0), i1power(-1.0 / Jm))]),
            (1.0, None, [(logpoly(0.5 * k0), unity)]),
        ]
    if name == "VerondaWestmann":
        c1, c2, k0 = p["c1"], p["c2"], p["k0"]
        return [
            (c1 * math.exp(-3.0 * c2), phi_exp, [(jpower(-2.0 / 3.0), i1power(c2))]),
            (
                1.0,
                None,
                [
                    (jpower(-4.0 / 3.0), linear_i2(-0.5 * c1 * c2)),
                    (logpoly(0.5 * k0, 0.0, 1.5 * c1 * c2 - c1), unity),
                ],
            ),
        ]
    if name == "Demiray":
        a, b, k0 = p["a"], p["b"], p["k0"]
        return [
            (a / (2.0 * b) * math.exp(-3.0 * b), phi_exp, [(jpower(-2.0 / 3.0), i1power(b))]),
            (1.0, None, [(logpoly(0.5 * k0, 0.0, -a / (2.0 * b)), unity)]),
        ]
    if name == "Ogden":
        mu, alpha, k0 = p["mu"], p["alpha"], p["k0"]
        c = mu / alpha**2
        return [
            (
                1.0,
                None,
                [
                    (jpower(-alpha / 3.0), eigen_power_sum(c, 0.5 * alpha)),
                    (logpoly(0.5 * k0, 0.0, -3.0 * c), unity),
                ],
            )
        ]
    if name == "StVenantKirchhoff":
        return [(1.0, None, [(jpower(0.0), green_quadratic(p["mu"], p["lam"]))])]
    if name == "Costa":
        B = np.array(
            [
                [p["b_ff"], p["b_fs"], p["b_fn"]],
                [p["b_fs"], p["b_ss"], p["b_sn"]],
                [p["b_fn"], p["b_sn"], p["b_nn"]],
            ],
            dtype=REAL,
        )
        half_a = 0.5 * p["a"]
        return [
            (half_a, phi_exp, [(jpower(-4.0 / 3.0), fibre_quadratic(B, R))]),
            (1.0, None, [(jlogj(p["k0"], -half_a), unity)]),
        ]
    raise SystemExit(f"unknown material {name}")


# ------------------------------------------------------------------ the element


def geometry(X, cells):
    Xc = X[cells]
    Dm = np.stack([Xc[:, 1] - Xc[:, 0], Xc[:, 2] - Xc[:, 0], Xc[:, 3] - Xc[:, 0]], axis=2)
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)
    D = np.empty((len(cells), 4, 3), dtype=REAL)
    D[:, 1:] = Dinv
    D[:, 0] = -Dinv.sum(axis=1)
    return D, V0


def frames(arrays, m):
    if "frame" not in arrays:
        return np.broadcast_to(np.eye(3, dtype=REAL), (m, 3, 3))
    R = np.asarray(arrays["frame"], dtype=REAL)
    return np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R


def term_derivatives(fJ, gC, J, dJ, d2J, F, C, D):
    """Value (m,), gradient (m, 4, 3) and Hessian (m, 4, 4, 3, 3) of f(J) g(C)."""
    m = len(J)
    f, f1, f2 = fJ(J)
    g, G, dG = gC(C)
    dg = 2.0 * np.einsum("mkI,mIJ,maJ->mak", F, G, D)
    # directions: node b, component k -> dF = e_k (x) D_b, dC = dF^T F + F^T dF
    FtE = np.transpose(F, (0, 2, 1))  # (m, I, k): F^T e_k is column k
    dC = np.einsum("mbI,mJk->mbkIJ", D, FtE)
    dC = dC + np.swapaxes(dC, -1, -2)
    dGd = dG(dC.reshape(m, 12, 3, 3)).reshape(m, 4, 3, 3, 3)
    d2g = 2.0 * np.einsum("maI,mIJ,mbJ->mab", D, G, D)[..., None, None] * EYE
    d2g = d2g + 2.0 * np.einsum("miI,mbkIJ,maJ->mabik", F, dGd, D)
    fa, f1a, f2a = (np.broadcast_to(v, J.shape) for v in (f, f1, f2))
    value = fa * g
    grad = (f1a * g)[:, None, None] * dJ + fa[:, None, None] * dg
    hess = (f2a * g)[:, None, None, None, None] * np.einsum("mai,mbk->mabik", dJ, dJ)
    cross = np.einsum("mai,mbk->mabik", dJ, dg) + np.einsum("mai,mbk->mabik", dg, dJ)
    hess = hess + f1a[:, None, None, None, None] * cross
    hess = hess + (f1a * g)[:, None, None, None, None] * d2J
    hess = hess + fa[:, None, None, None, None] * d2g
    return value, grad, hess


def solve(case, arrays):
    model = case["model"]
    name = model["name"]
    p = parameters(model)
    X = np.asarray(arrays["points"], dtype=REAL)
    x = np.asarray(arrays["positions"], dtype=REAL)
    cells = np.asarray(arrays["cells"], dtype=np.int64)
    n, m = len(X), len(cells)
    D, V0 = geometry(X, cells)

    F = np.einsum("mak,maI->mkI", x[cells], D)
    J = np.linalg.det(F)
    C = np.einsum("mkI,mkJ->mIJ", F, F)
    Finv = np.linalg.inv(F)
    a = np.einsum("mIk,maI->mak", Finv, D)  # F^-T D_a
    dJ = J[:, None, None] * a
    aa = np.einsum("mai,mbk->mabik", a, a)
    d2J = J[:, None, None, None, None] * (aa - np.einsum("mbi,mak->mabik", a, a))

    W = np.zeros(m, dtype=REAL)
    dW = np.zeros((m, 4, 3), dtype=REAL)
    d2W = np.zeros((m, 4, 4, 3, 3), dtype=REAL)
    for coef, phi, terms in term_table(name, p, frames(arrays, m)):
        u = np.zeros(m, dtype=REAL)
        du = np.zeros((m, 4, 3), dtype=REAL)
        d2u = np.zeros((m, 4, 4, 3, 3), dtype=REAL)
        for fJ, gC in terms:
            t, dt, d2t = term_derivatives(fJ, gC, J, dJ, d2J, F, C, D)
            u, du, d2u = u + t, du + dt, d2u + d2t
        if phi is None:
            W, dW, d2W = W + coef * u, dW + coef * du, d2W + coef * d2u
            continue
        h0, h1, h2 = phi(u)
        W = W + coef * h0
        dW = dW + (coef * h1)[:, None, None] * du
        outer = np.einsum("mai,mbk->mabik", du, du)
        d2W = d2W + (coef * h2)[:, None, None, None, None] * outer
        d2W = d2W + (coef * h1)[:, None, None, None, None] * d2u

    fe = -V0[:, None, None] * dW
    Ke = V0[:, None, None, None, None] * d2W
    Ke = np.transpose(Ke, (0, 1, 3, 2, 4)).reshape(m, 12, 12)

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
