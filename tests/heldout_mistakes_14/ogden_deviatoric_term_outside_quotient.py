#!/usr/bin/env python3
# MISTAKE: principal stresses hand-written S_a = mu/alpha J^(-alpha/3) (lambda_a^(alpha - 2) -
# T/3) + k0 ln J / lambda_a^2, the 1/lambda_a^2 of S_a = tau_a / lambda_a^2 applied to the first
# term only, where mu/alpha J^(-alpha/3) (lambda_a^alpha - T/3) / lambda_a^2 belongs (T = sum
# lambda^alpha): force and stiffness wrong in both states; energy right.
"""P1 tetrahedral hyperelastic engine in principal stretches (Simo-Taylor spectral form).

Vectorised over the m cells with NumPy (no Python loop over cells). Precomputed from the rest
edge matrix Dm = [X1 - X0, X2 - X0, X3 - X0]: the shape-function gradients G_a (rows of
Dm^-1, G_0 = -(G_1 + G_2 + G_3)) and the rest volumes V0 = det(Dm) / 6. At the current state:
F = sum_a x_a (x) G_a, C = F^T F, and the eigen-decomposition C = sum_a c_a N_a (x) N_a
(numpy.linalg.eigh), principal stretches lambda_a = sqrt(c_a). Isotropic materials are
evaluated in the principal stretches: W(lambda_1, lambda_2, lambda_3) through second-order
jets (value, gradient, Hessian), either over the invariants (I1, I2, J) computed from the
stretches and chained to the stretches, or directly in the stretches (Ogden, St
Venant-Kirchhoff); principal second Piola-Kirchhoff stresses S_a = (1/lambda_a) dW/dlambda_a,
S = sum_a S_a N_a (x) N_a; material tangent CC = 2 dS/dC in spectral form: on the principal
axes CC_aabb = (1/(lambda_a lambda_b)) d2W/dlambda_a dlambda_b - delta_ab S_a / lambda_a^2,
and between distinct directions CC_abab = CC_abba = (S_a - S_b) / (c_a - c_b), written without
cancellation (the invariant partials for invariant materials, expm1 quotients for Ogden), so
that coincident and nearly coincident eigenvalues are exact. Costa (anisotropic) in its
per-cell fibre frame: Ef = R^T E R, Q = sum B_ij Ef_ij^2, closed-form S and CC. Then
P = F S, A_iJkL = delta_ik S_JL + F_iI F_kK CC_IJKL, element force f_a = -V0 P G_a, element
stiffness K_ab = V0 G_a . A . G_b, assembled through the (m, 12) node-major dof map into a
dense, COO or CSR stiffness; energy sum V0 W.

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
COSTA_B = ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")


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
# A jet is (value (m,), gradient (m, k), Hessian (m, k, k)) over k independent variables.


def jvar(value, k, i):
    g = np.zeros(value.shape + (k,), dtype=REAL)
    g[..., i] = 1.0
    return value, g, np.zeros(value.shape + (k, k), dtype=REAL)


def jconst(c, like):
    v, g, h = like
    return np.full_like(v, c), np.zeros_like(g), np.zeros_like(h)


def jadd(a, b):
    return a[0] + b[0], a[1] + b[1], a[2] + b[2]


def jscale(s, a):
    return s * a[0], s * a[1], s * a[2]


def jshift(a, s):
    return a[0] + s, a[1], a[2]


def jmul(a, b):
    av, ag, ah = a
    bv, bg, bh = b
    outer = ag[..., :, None] * bg[..., None, :]
    hess = av[..., None, None] * bh + bv[..., None, None] * ah + outer + np.swapaxes(outer, -1, -2)
    return av * bv, av[..., None] * bg + bv[..., None] * ag, hess


def jfun(a, f0, f1, f2):
    """Composition f(a) given f, f' and f'' evaluated at a's value."""
    av, ag, ah = a
    hess = f2[..., None, None] * ag[..., :, None] * ag[..., None, :] + f1[..., None, None] * ah
    return f0, f1[..., None] * ag, hess


def jpow(a, q):
    v = a[0]
    return jfun(a, v**q, q * v ** (q - 1.0), q * (q - 1.0) * v ** (q - 2.0))


def jlog(a):
    v = a[0]
    return jfun(a, np.log(v), 1.0 / v, -1.0 / v**2)


def jexp(a):
    e = np.exp(a[0])
    return jfun(a, e, e, e)


# ------------------------------------------------------------------ materials


def volumetric(J, k0):
    lnJ = jlog(J)
    return jscale(0.5 * k0, jmul(lnJ, lnJ))


def invariant_energy(name, p, I1, I2, J):
    """W as a jet over (I1, I2, J), the invariants taken as independent variables."""
    if name == "NeoHookean":
        lnJ = jlog(J)
        W = jscale(0.5 * p["mu"], jshift(I1, -3.0))
        W = jadd(W, jscale(-p["mu"], lnJ))
        return jadd(W, jscale(0.5 * p["lam"], jmul(lnJ, lnJ)))
    if name == "StVenantKirchhoff":
        # lam/2 (tr E)^2 + mu tr(E^2), tr E = (I1 - 3)/2, tr(E^2) = (I1^2 - 2 I2 - 2 I1 + 3)/4
        trE = jscale(0.5, jshift(I1, -3.0))
        trE2 = jadd(jmul(I1, I1), jadd(jscale(-2.0, I2), jscale(-2.0, I1)))
        trE2 = jscale(0.25, jshift(trE2, 3.0))
        return jadd(jscale(0.5 * p["lam"], jmul(trE, trE)), jscale(p["mu"], trE2))
    I1b = jmul(jpow(J, -2.0 / 3.0), I1)
    I2b = jmul(jpow(J, -4.0 / 3.0), I2)
    x1 = jshift(I1b, -3.0)
    if name == "MooneyRivlin":
        W = jadd(jscale(p["c1"], x1), jscale(p["c2"], jshift(I2b, -3.0)))
    elif name == "Yeoh":
        x2 = jmul(x1, x1)
        W = jadd(jscale(p["c10"], x1), jscale(p["c20"], x2))
        W = jadd(W, jscale(p["c30"], jmul(x2, x1)))
    elif name == "ArrudaBoyce":
        W = jconst(0.0, x1)
        for i, c in enumerate(AB_C, start=1):
            term = jshift(jpow(I1b, float(i)), -(3.0**i))
            W = jadd(W, jscale(p["mu"] * c * p["N"] ** (1 - i), term))
    elif name == "Gent":
        arg = jshift(jscale(-1.0 / p["Jm"], x1), 1.0)
        W = jscale(-0.5 * p["mu"] * p["Jm"], jlog(arg))
    elif name == "VerondaWestmann":
        W = jscale(p["c1"], jshift(jexp(jscale(p["c2"], x1)), -1.0))
        W = jadd(W, jscale(-0.5 * p["c1"] * p["c2"], jshift(I2b, -3.0)))
    elif name == "Demiray":
        W = jscale(p["a"] / (2.0 * p["b"]), jshift(jexp(jscale(p["b"], x1)), -1.0))
    else:
        raise ValueError(name)
    return jadd(W, volumetric(J, p["k0"]))


def invariant_material(name, p, lam):
    """W, dW/dlambda (m, 3), d2W/dlambda2 (m, 3, 3) and the shear moduli theta (m, 3, 3)."""
    c = lam * lam
    Jv = lam[:, 0] * lam[:, 1] * lam[:, 2]
    I1v = c.sum(axis=1)
    I2v = c[:, 0] * c[:, 1] + c[:, 1] * c[:, 2] + c[:, 0] * c[:, 2]
    W = invariant_energy(name, p, jvar(I1v, 3, 0), jvar(I2v, 3, 1), jvar(Jv, 3, 2))
    eye = np.eye(3, dtype=REAL)
    off = 1.0 - eye
    # invariants as functions of the stretches: gradients (m, 3) and Hessians (m, 3, 3)
    dI1 = 2.0 * lam
    d2I1 = np.broadcast_to(2.0 * eye, (len(lam), 3, 3))
    dI2 = 2.0 * lam * (I1v[:, None] - c)
    d2I2 = (
        4.0 * lam[:, :, None] * lam[:, None, :] * off + eye * (2.0 * (I1v[:, None] - c))[:, :, None]
    )
    dJ = Jv[:, None] / lam
    d2J = Jv[:, None, None] / (lam[:, :, None] * lam[:, None, :]) * off
    dInv = np.stack([dI1, dI2, dJ], axis=1)
    d2Inv = np.stack([d2I1, d2I2, d2J], axis=1)
    Wv, Wg, Wh = W
    dW = np.einsum("mk,mka->ma", Wg, dInv)
    d2W = np.einsum("mkl,mka,mlb->mab", Wh, dInv, dInv) + np.einsum("mk,mkab->mab", Wg, d2Inv)
    # S_a = 2 W_1 + 2 W_2 (I1 - c_a) + W_J J / c_a: (S_a - S_b)/(c_a - c_b), no cancellation
    theta = -2.0 * Wg[:, 1, None, None] - Wg[:, 2, None, None] * Jv[:, None, None] / (
        c[:, :, None] * c[:, None, :]
    )
    return Wv, dW, d2W, theta


def power_quotient(ca, cb, q):
    """(ca^q - cb^q) / (ca - cb) without cancellation (q ca^(q-1) where they coincide)."""
    r = np.log(ca / cb)
    small = np.abs(r) < 1e-6
    rs = np.where(small, 1.0, r)
    ratio = np.where(small, q * (1.0 + 0.5 * (q - 1.0) * r), np.expm1(q * rs) / np.expm1(rs))
    return cb ** (q - 1.0) * ratio


def stretch_material(name, p, lam):
    """Ogden and St Venant-Kirchhoff directly in the stretches (jets over lambda_1..3)."""
    L = [jvar(lam[:, a], 3, a) for a in range(3)]
    c = lam * lam
    if name == "StVenantKirchhoff":
        E = [jscale(0.5, jshift(jmul(La, La), -1.0)) for La in L]
        trE = jadd(jadd(E[0], E[1]), E[2])
        trE2 = jadd(jadd(jmul(E[0], E[0]), jmul(E[1], E[1])), jmul(E[2], E[2]))
        W = jadd(jscale(0.5 * p["lam"], jmul(trE, trE)), jscale(p["mu"], trE2))
        theta = np.broadcast_to(p["mu"], (len(lam), 3, 3)).astype(REAL)
        return W[0], W[1], W[2], theta
    mu, al, k0 = p["mu"], p["alpha"], p["k0"]
    J = jmul(jmul(L[0], L[1]), L[2])
    T = jadd(jadd(jpow(L[0], al), jpow(L[1], al)), jpow(L[2], al))
    g = jpow(J, -al / 3.0)
    W = jadd(jscale(mu / al**2, jshift(jmul(g, T), -3.0)), volumetric(J, k0))
    # S_a = mu/alpha g (c_a^(alpha/2 - 1) - T/(3 c_a)) + k0 ln J / c_a
    gv, Tv, lnJ = g[0], T[0], np.log(J[0])
    ca, cb = c[:, :, None], c[:, None, :]
    dd = power_quotient(ca, cb, 0.5 * al - 1.0)
    theta = mu / al * gv[:, None, None] * (dd + Tv[:, None, None] / (3.0 * ca * cb))
    theta = theta - k0 * lnJ[:, None, None] / (ca * cb)
    return W[0], W[1], W[2], theta


def spectral_stress_tangent(name, p, C):
    c, N = np.linalg.eigh(C)
    lam = np.sqrt(c)
    if name in ("Ogden", "StVenantKirchhoff"):
        W, dW, d2W, theta = stretch_material(name, p, lam)
    else:
        W, dW, d2W, theta = invariant_material(name, p, lam)
    Sa = dW / lam
    if name == "Ogden":  # principal stresses written out: tau_a / lambda_a^2
        al, Jl = p["alpha"], lam.prod(axis=1)
        T = (lam**al).sum(axis=1)
        Sa = p["mu"] / al * Jl[:, None] ** (-al / 3.0) * (lam ** (al - 2.0) - T[:, None] / 3.0)
        Sa = Sa + p["k0"] * np.log(Jl)[:, None] / c
    S = np.einsum("mIa,ma,mJa->mIJ", N, Sa, N)
    eye = np.eye(3, dtype=REAL)
    Chat = np.zeros((len(c), 3, 3, 3, 3), dtype=REAL)
    diag = d2W / (lam[:, :, None] * lam[:, None, :]) - eye * (Sa / c)[:, :, None]
    for a in range(3):
        for b in range(3):
            Chat[:, a, a, b, b] = diag[:, a, b]
            if a != b:
                Chat[:, a, b, a, b] += theta[:, a, b]
                Chat[:, a, b, b, a] += theta[:, a, b]
    CC = np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", N, N, N, N, Chat, optimize=True)
    return W, S, CC


def costa_stress_tangent(p, C, R):
    eye = np.eye(3, dtype=REAL)
    Bm = np.array(
        [
            [p["b_ff"], p["b_fs"], p["b_fn"]],
            [p["b_fs"], p["b_ss"], p["b_sn"]],
            [p["b_fn"], p["b_sn"], p["b_nn"]],
        ],
        dtype=REAL,
    )
    E = 0.5 * (C - eye)
    Ef = np.einsum("mIa,mIJ,mJb->mab", R, E, R)
    Q = np.einsum("ab,mab->m", Bm, Ef * Ef)
    H = np.einsum("mIa,mab,mJb->mIJ", R, Bm * Ef, R)  # dQ/dC
    dH = 0.25 * (
        np.einsum("mIa,mJb,mMa,mNb,ab->mIJMN", R, R, R, R, Bm, optimize=True)
        + np.einsum("mIa,mJb,mMb,mNa,ab->mIJMN", R, R, R, R, Bm, optimize=True)
    )
    J = np.sqrt(np.linalg.det(C))
    Ci = np.linalg.inv(C)
    g = J ** (-4.0 / 3.0)
    Qh = g * Q
    e = np.exp(Qh)
    a, k0 = p["a"], p["k0"]
    W = 0.5 * a * (e - 1.0) + k0 * (J * np.log(J) - J + 1.0)
    dQh = g[:, None, None] * (H - 2.0 / 3.0 * Q[:, None, None] * Ci)
    CiCi = 0.5 * (np.einsum("mIK,mJL->mIJKL", Ci, Ci) + np.einsum("mIL,mJK->mIJKL", Ci, Ci))
    Cio = np.einsum("mIJ,mKL->mIJKL", Ci, Ci)
    d2Qh = g[:, None, None, None, None] * (
        -2.0 / 3.0 * np.einsum("mIJ,mKL->mIJKL", H - 2.0 / 3.0 * Q[:, None, None] * Ci, Ci)
        + dH
        - 2.0 / 3.0 * np.einsum("mIJ,mKL->mIJKL", Ci, H)
        + 2.0 / 3.0 * Q[:, None, None, None, None] * CiCi
    )
    S = a * e[:, None, None] * dQh + (k0 * J * np.log(J))[:, None, None] * Ci
    CC = 2.0 * a * e[:, None, None, None, None] * (np.einsum("mIJ,mKL->mIJKL", dQh, dQh) + d2Qh)
    CC = CC + (k0 * J * (np.log(J) + 1.0))[:, None, None, None, None] * Cio
    CC = CC - (2.0 * k0 * J * np.log(J))[:, None, None, None, None] * CiCi
    return W, S, CC


# ------------------------------------------------------------------ the engine


def geometry(X, cells):
    Dm = np.transpose(X[cells[:, 1:]] - X[cells[:, :1]], (0, 2, 1))
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)
    G = np.empty((len(cells), 4, 3), dtype=REAL)
    G[:, 1:] = Dinv
    G[:, 0] = -Dinv.sum(axis=1)
    return G, V0


def frames(case, arrays, m):
    R = np.asarray(arrays["frame"], dtype=REAL)
    return np.broadcast_to(R, (m, 3, 3)) if R.ndim == 2 else R


def solve(case, arrays):
    model = case["model"]
    name = model["name"]
    p = parameters(model)
    X = np.asarray(arrays["points"], dtype=REAL)
    x = np.asarray(arrays["positions"], dtype=REAL)
    cells = np.asarray(arrays["cells"], dtype=np.int64)
    n, m = len(X), len(cells)
    G, V0 = geometry(X, cells)

    F = np.einsum("mak,maI->mkI", x[cells], G)
    C = np.einsum("mkI,mkJ->mIJ", F, F)
    if name == "Costa":
        W, S, CC = costa_stress_tangent(p, C, frames(case, arrays, m))
    else:
        W, S, CC = spectral_stress_tangent(name, p, C)

    P = np.einsum("mkI,mIJ->mkJ", F, S)
    A = np.einsum("ik,mJL->miJkL", np.eye(3, dtype=REAL), S)
    A = A + np.einsum("miI,mkK,mIJKL->miJkL", F, F, CC, optimize=True)
    fe = -V0[:, None, None] * np.einsum("mkJ,maJ->mak", P, G)
    Ke = V0[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, A, G, optimize=True)
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
