#!/usr/bin/env python3
# MISTAKE: tangent of the Jaumann rate of the Kirchhoff stress (Abaqus UMAT's DDSDDE / J: c +
# (delta_ik sigma_jl + sigma_ik delta_jl + delta_il sigma_jk + sigma_il delta_jk)/2) used as the
# spatial tangent c beside the geometric stiffness: the rate correction is not subtracted
# (stiffness only).
"""Updated-Lagrangian (spatial) engine for NeoHookean on linear tetrahedra, one kit case.

Per cell: F, J, b = F F^T, the Cauchy stress sigma and the spatial elasticity tensor c from
the derivatives of W by its invariants, pushed forward with F; spatial gradients
grad N = D F^-1; internal force int sigma grad N dv over the deformed volume v = J V;
stiffness B^T c B v (6x6 Voigt, FEBio order xx yy zz xy yz xz) plus the initial-stress part
(grad N_a . sigma grad N_b) v I; element triplets written as COO.

Usage: python ENGINE INPUT_DIR OUTPUT_DIR (exchange format of docs/conventions.md).
"""

import json
import sys
from pathlib import Path

import numpy as np

DTYPE = np.float64
EXT = ".f64"
OUT_DTYPE = "<f8"
# FEBio's Voigt order: xx, yy, zz, xy, yz, xz
VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
EYE = np.eye(3, dtype=DTYPE)


# ----------------------------------------------------------------------------- input
def read_case(folder):
    folder = Path(folder)
    case = json.loads((folder / "case.json").read_text())
    if case.get("format_version") != 1:
        raise SystemExit("unknown case format_version")
    arrays = {}
    for name, spec in case["arrays"].items():
        raw = np.fromfile(folder / spec["file"], dtype=spec["dtype"])
        arrays[name] = raw.reshape(spec["shape"])
    return case["model"], arrays


# ----------------------------------------------------------------------------- jets
class Jet:
    """A per-cell scalar with its gradient and Hessian by the invariants (exact second order)."""

    def __init__(self, val, grad, hess):
        self.val, self.grad, self.hess = val, grad, hess

    @staticmethod
    def variable(val, index, count):
        grad = np.zeros(val.shape + (count,), dtype=DTYPE)
        grad[..., index] = 1.0
        return Jet(val, grad, np.zeros(val.shape + (count, count), dtype=DTYPE))

    def _lift(self, other):
        if isinstance(other, Jet):
            return other
        val = np.broadcast_to(np.asarray(other, dtype=DTYPE), self.val.shape)
        return Jet(val, np.zeros_like(self.grad), np.zeros_like(self.hess))

    def __add__(self, other):
        o = self._lift(other)
        return Jet(self.val + o.val, self.grad + o.grad, self.hess + o.hess)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.val, -self.grad, -self.hess)

    def __sub__(self, other):
        return self + (-self._lift(other))

    def __rsub__(self, other):
        return self._lift(other) - self

    def __mul__(self, other):
        o = self._lift(other)
        outer = np.einsum("...i,...j->...ij", self.grad, o.grad)
        hess = self.val[..., None, None] * o.hess + o.val[..., None, None] * self.hess
        return Jet(
            self.val * o.val,
            self.val[..., None] * o.grad + o.val[..., None] * self.grad,
            hess + outer + np.swapaxes(outer, -1, -2),
        )

    __rmul__ = __mul__

    def chain(self, f, df, d2f):
        outer = np.einsum("...i,...j->...ij", self.grad, self.grad)
        return Jet(
            f,
            df[..., None] * self.grad,
            d2f[..., None, None] * outer + df[..., None, None] * self.hess,
        )

    def __pow__(self, p):
        v = self.val
        return self.chain(v**p, p * v ** (p - 1), p * (p - 1) * v ** (p - 2))

    def exp(self):
        e = np.exp(self.val)
        return self.chain(e, e, e)

    def log(self):
        v = self.val
        return self.chain(np.log(v), 1.0 / v, -1.0 / (v * v))


# ----------------------------------------------------------------------------- material
MATERIAL = "NeoHookean"
INVARIANTS = ("I1", "J")


def strain_energy(inv, p):
    """W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2, split (isochoric-like part, J part)."""
    I1, J = inv["I1"], inv["J"]
    lnJ = J.log()
    return 0.5 * p["mu"] * (I1 - 3.0), -p["mu"] * lnJ + 0.5 * p["lam"] * lnJ * lnJ


# ----------------------------------------------------------------------------- tensors
def sym_product(A, B):
    """(A o B)_ijkl = (A_ik B_jl + A_il B_jk) / 2, per cell."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def dyad(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def divided_power(ei, ej, p):
    """(ei^p - ej^p) / (ei - ej), and p ei^(p-1) in the limit, without cancellation."""
    L = np.log(ei / ej)
    small = np.abs(L) < 1e-300
    Ls = np.where(small, 1.0, L)
    ratio = np.where(small, p, np.expm1(p * Ls) / np.expm1(Ls))
    return ej ** (p - 1) * ratio


def invariant_tensors(names, F, b, J, params, frame):
    """Values of the invariants, and their first and second derivatives by C pushed forward
    with F: G = F (dI/dC) F^T and H = F F (d2I/dCdC) F^T F^T.
    """
    m = F.shape[0]
    eye = np.broadcast_to(EYE, (m, 3, 3))
    vals, G, H = {}, {}, {}
    I1 = np.einsum("mii->m", b)
    bb = b @ b
    for name in names:
        if name == "I1":
            vals[name], G[name], H[name] = I1, b, None
        elif name == "I2":
            vals[name] = 0.5 * (I1 * I1 - np.einsum("mii->m", bb))
            G[name] = I1[:, None, None] * b - bb
            H[name] = dyad(b, b) - sym_product(b, b)
        elif name == "J":
            vals[name] = J
            G[name] = 0.5 * J[:, None, None] * eye
            H[name] = J[:, None, None, None, None] * (
                0.25 * dyad(eye, eye) - 0.5 * sym_product(eye, eye)
            )
        elif name == "g":  # Ogden: g = sum_i e_i^(alpha/2), e_i the eigenvalues of b (and of C)
            alpha = params["alpha"]
            e, N = np.linalg.eigh(b)
            vals[name] = np.sum(e ** (0.5 * alpha), axis=1)
            G[name] = 0.5 * alpha * np.einsum("mi,mai,mbi->mab", e ** (0.5 * alpha), N, N)
            q = 0.5 * alpha - 1.0
            M = e[:, :, None] * e[:, None, :] * divided_power(e[:, :, None], e[:, None, :], q)
            T = np.einsum("mij,mai,mbj,mci,mdj->mabcd", M, N, N, N, N)
            T = T + np.einsum("mij,mai,mbj,mcj,mdi->mabcd", M, N, N, N, N)
            H[name] = 0.25 * alpha * T
        elif name == "Q":  # Costa: Q = sum B_pq Ef_pq^2, Ef = (A^T A - I) / 2, A = F R
            Bm = np.array(
                [
                    [params["b_ff"], params["b_fs"], params["b_fn"]],
                    [params["b_fs"], params["b_ss"], params["b_sn"]],
                    [params["b_fn"], params["b_sn"], params["b_nn"]],
                ],
                dtype=DTYPE,
            )
            A = F @ frame
            Ef = 0.5 * (np.einsum("mkp,mkq->mpq", A, A) - eye)
            vals[name] = np.einsum("pq,mpq->m", Bm, Ef * Ef)
            G[name] = A @ (Bm * Ef) @ np.swapaxes(A, 1, 2)
            T = np.einsum("pq,mip,mjq,mkp,mlq->mijkl", Bm, A, A, A, A)
            T = T + np.einsum("pq,mip,mjq,mlp,mkq->mijkl", Bm, A, A, A, A)
            H[name] = 0.25 * T
    return vals, G, H


# ----------------------------------------------------------------------------- constitutive
def cauchy_and_tangent(F, params, frame):
    """Cauchy stress sigma (m, 3, 3), spatial elasticity tensor c (m, 3, 3, 3, 3) and the
    energy density W (m,) of every cell.
    """
    J = np.linalg.det(F)
    b = F @ np.swapaxes(F, 1, 2)
    vals, G, H = invariant_tensors(INVARIANTS, F, b, J, params, frame)
    jets = [Jet.variable(vals[n], i, len(INVARIANTS)) for i, n in enumerate(INVARIANTS)]
    iso, vol = strain_energy(dict(zip(INVARIANTS, jets)), params)
    W = iso + vol
    tau = np.zeros_like(F)
    cJ = np.zeros(F.shape[:1] + (3, 3, 3, 3), dtype=DTYPE)
    for a, na in enumerate(INVARIANTS):
        wa = W.grad[:, a]
        tau += 2.0 * wa[:, None, None] * G[na]
        if H[na] is not None:
            cJ += 4.0 * wa[:, None, None, None, None] * H[na]
        for c, nc in enumerate(INVARIANTS):
            cJ += 4.0 * W.hess[:, a, c][:, None, None, None, None] * dyad(G[na], G[nc])
    sigma = tau / J[:, None, None]
    c = cJ / J[:, None, None, None, None]
    # tangent handed over as a UMAT's DDSDDE (Jaumann rate)
    eye = np.broadcast_to(EYE, sigma.shape)
    c = c + 0.5 * (
        np.einsum("mik,mjl->mijkl", eye, sigma)
        + np.einsum("mik,mjl->mijkl", sigma, eye)
        + np.einsum("mil,mjk->mijkl", eye, sigma)
        + np.einsum("mil,mjk->mijkl", sigma, eye)
    )
    return sigma, c, iso.val + vol.val, J


def voigt_stress(sigma):
    return np.stack([sigma[:, i, j] for i, j in VOIGT], axis=1)


def voigt_tangent(c):
    return np.stack(
        [np.stack([c[:, i, j, k, l] for k, l in VOIGT], axis=1) for i, j in VOIGT], axis=1
    )


def strain_displacement(grad):
    """B (m, 6, 12): engineering strain rates (shear rows d_ij + d_ji) from node velocities."""
    m = grad.shape[0]
    Bm = np.zeros((m, 6, 4, 3), dtype=DTYPE)
    for A, (i, j) in enumerate(VOIGT):
        Bm[:, A, :, i] += grad[:, :, j]
        if i != j:
            Bm[:, A, :, j] += grad[:, :, i]
    return Bm.reshape(m, 6, 12)


# ----------------------------------------------------------------------------- element loop
def element_arrays(X, x, cells, params, frame):
    Xe, xe = X[cells], x[cells]
    M = np.stack([Xe[:, 1] - Xe[:, 0], Xe[:, 2] - Xe[:, 0], Xe[:, 3] - Xe[:, 0]], axis=2)
    V = np.linalg.det(M) / 6.0
    Minv = np.linalg.inv(M)
    D = np.empty((cells.shape[0], 4, 3), dtype=DTYPE)
    D[:, 1:] = Minv
    D[:, 0] = -Minv.sum(axis=1)
    F = np.einsum("mak,mai->mki", xe, D)
    sigma, c, W, J = cauchy_and_tangent(F, params, frame)
    Finv = np.linalg.inv(F)
    grad = np.einsum("mai,mij->maj", D, Finv)  # spatial gradients grad N_a = F^-T D_a
    v = J * V  # deformed volume
    Bm = strain_displacement(grad)
    s = voigt_stress(sigma)
    Dv = voigt_tangent(c)
    fe = -np.einsum("mAr,mA->mr", Bm, s) * v[:, None]  # f = -dPi/dx
    Kmat = np.einsum("mAr,mAB,mBs->mrs", Bm, Dv, Bm) * v[:, None, None]
    Gab = np.einsum("mai,mij,mbj->mab", grad, sigma, grad) * v[:, None, None]
    Kgeo = np.einsum("mab,ik->maibk", Gab, EYE).reshape(-1, 12, 12)
    Ke = Kmat + Kgeo
    energy = np.sum(V * W)
    return fe, Ke, energy


# ----------------------------------------------------------------------------- output
def element_dofs(cells):
    return (3 * cells[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12)


def write_outputs(out, n, cells, fe, Ke, energy):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    dofs = element_dofs(cells)
    force = np.bincount(dofs.ravel(), weights=fe.ravel(), minlength=3 * n)
    force.astype(OUT_DTYPE).tofile(out / ("force" + EXT))
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    np.asarray(rows, dtype="<i8").tofile(out / "stiffness_rows.i64")
    np.asarray(cols, dtype="<i8").tofile(out / "stiffness_cols.i64")
    Ke.ravel().astype(OUT_DTYPE).tofile(out / ("stiffness_values" + EXT))
    np.array([energy], dtype=DTYPE).astype(OUT_DTYPE).tofile(out / ("energy" + EXT))


def main(argv):
    if len(argv) != 3:
        raise SystemExit(f"usage: {argv[0]} INPUT_DIR OUTPUT_DIR")
    model, arrays = read_case(argv[1])
    if model.get("kind") != "material" or model.get("name") != MATERIAL:
        raise SystemExit(f"this engine computes {MATERIAL} only, not {model.get('name')}")
    params = {k: float(v) for k, v in model["parameters"].items()}
    X = arrays["points"].astype(DTYPE)
    x = arrays["positions"].astype(DTYPE)
    cells = arrays["cells"].astype(np.int64)
    frame = arrays["frame"].astype(DTYPE) if "frame" in arrays else None
    fe, Ke, energy = element_arrays(X, x, cells, params, frame)
    write_outputs(argv[2], X.shape[0], cells, fe, Ke, energy)


if __name__ == "__main__":
    main(sys.argv)
