#!/usr/bin/env python3
# VerondaWestmann: tetrahedron volume det/24 instead of det/6
"""Hyperelastic force and stiffness on linear tetrahedra for one mjed-verify kit case.

Usage: python THIS_FILE INPUT_DIR OUTPUT_DIR

Written from docs/conventions.md (exchange format version 1) with NumPy only: the energy is
evaluated with a small forward-mode second-order jet over the nine entries of F, so the
first Piola stress and its derivative come out of the same code path.
"""

import json
import sys
from pathlib import Path

import numpy as np

REAL = np.float64


# ----------------------------------------------------------------------------- input
def read_case(inp):
    meta = json.loads((inp / "case.json").read_text())
    if meta.get("format_version") != 1:
        raise SystemExit(f"unknown case format_version {meta.get('format_version')!r}")
    arrays = {}
    for name, spec in meta["arrays"].items():
        a = np.fromfile(inp / spec["file"], dtype=np.dtype(spec["dtype"]))
        arrays[name] = a.reshape(spec["shape"])
    return meta, arrays


def geometry(X, cells):
    """Rest volumes V0 (m,) and shape-function gradients D (m, 4, 3) of every cell."""
    Xe = X[cells]
    M = np.stack([Xe[:, 1] - Xe[:, 0], Xe[:, 2] - Xe[:, 0], Xe[:, 3] - Xe[:, 0]], axis=2)
    V0 = np.linalg.det(M) / 24.0
    Minv = np.linalg.inv(M)  # rows: D_1, D_2, D_3
    D = np.empty(Xe.shape, dtype=X.dtype)
    D[:, 1:] = Minv
    D[:, 0] = -Minv.sum(axis=1)
    return V0, D


def deformation_gradient(x, cells, D):
    """F[m, k, i] = sum_a x_a[k] D_a[i]."""
    return np.einsum("mak,mai->mki", x[cells], D)


# ----------------------------------------------------------------------------- jets
class Jet:
    """Value, gradient and Hessian of a scalar per cell, w.r.t. the 9 entries of F."""

    __array_ufunc__ = None  # let ndarray * Jet reach Jet.__rmul__

    def __init__(self, v, g, h):
        self.v, self.g, self.h = v, g, h

    @staticmethod
    def lift(c, like):
        if isinstance(c, Jet):
            return c
        v = np.broadcast_to(np.asarray(c, dtype=like.v.dtype), like.v.shape).copy()
        return Jet(v, np.zeros_like(like.g), np.zeros_like(like.h))

    def __add__(self, o):
        if isinstance(o, Jet):
            return Jet(self.v + o.v, self.g + o.g, self.h + o.h)
        return Jet(self.v + o, self.g, self.h)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.v, -self.g, -self.h)

    def __sub__(self, o):
        return self + (-o)

    def __rsub__(self, o):
        return (-self) + o

    def __mul__(self, o):
        if isinstance(o, Jet):
            outer = self.g[:, :, None] * o.g[:, None, :]
            return Jet(
                self.v * o.v,
                self.v[:, None] * o.g + o.v[:, None] * self.g,
                self.v[:, None, None] * o.h
                + o.v[:, None, None] * self.h
                + outer
                + outer.transpose(0, 2, 1),
            )
        o = np.asarray(o, dtype=self.v.dtype)
        if o.ndim == 1:
            return Jet(self.v * o, self.g * o[:, None], self.h * o[:, None, None])
        return Jet(self.v * o, self.g * o, self.h * o)

    __rmul__ = __mul__

    def unary(self, f0, f1, f2):
        gg = self.g[:, :, None] * self.g[:, None, :]
        return Jet(f0, f1[:, None] * self.g, f1[:, None, None] * self.h + f2[:, None, None] * gg)

    def __pow__(self, p):
        v = self.v
        return self.unary(v**p, p * v ** (p - 1), p * (p - 1) * v ** (p - 2))

    def __truediv__(self, o):
        if isinstance(o, Jet):
            return self * o**-1
        return self * (1.0 / np.asarray(o, dtype=self.v.dtype))

    def __rtruediv__(self, o):
        return self**-1 * o


def jexp(a):
    e = np.exp(a.v)
    return a.unary(e, e, e)


def jlog(a):
    return a.unary(np.log(a.v), 1.0 / a.v, -1.0 / a.v**2)


def matmul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def transpose(A):
    return [[A[j][i] for j in range(3)] for i in range(3)]


def trace(A):
    return A[0][0] + A[1][1] + A[2][2]


def det3(A):
    return (
        A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1])
        - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0])
        + A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0])
    )


def as_rows(R):
    """A NumPy (m, 3, 3) array as nested lists of per-cell columns (for matmul with jets)."""
    return [[R[:, i, j] for j in range(3)] for i in range(3)]


def deformation_jets(F):
    """F (m, 3, 3) -> nested 3x3 list of jets, variable 3*k + i is F[k, i]."""
    m = F.shape[0]
    rows = []
    for k in range(3):
        row = []
        for i in range(3):
            g = np.zeros((m, 9), dtype=F.dtype)
            g[:, 3 * k + i] = 1.0
            row.append(Jet(F[:, k, i].copy(), g, np.zeros((m, 9, 9), dtype=F.dtype)))
        rows.append(row)
    return rows


# ----------------------------------------------------------------------------- material
MATERIAL = "VerondaWestmann"


def invariants(F):
    """J, ln J, I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2 of the jets F."""
    C = matmul(transpose(F), F)
    J = det3(F)
    I1 = trace(C)
    I2 = 0.5 * (I1 * I1 - trace(matmul(C, C)))
    return J, jlog(J), J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2


def strain_energy(F, p, frame):
    """W = c1 (exp(c2 (I1b - 3)) - 1) - c1 c2/2 (I2b - 3) + k0/2 (ln J)^2."""
    c1, c2, k0 = p["c1"], p["c2"], p["k0"]
    J, lnJ, I1b, I2b = invariants(F)
    return c1 * (jexp(c2 * (I1b - 3.0)) - 1.0) - 0.5 * c1 * c2 * (I2b - 3.0) + 0.5 * k0 * lnJ * lnJ


# ----------------------------------------------------------------------------- element
def element_terms(X, x, cells, p, frame):
    V0, D = geometry(X, cells)
    F = deformation_gradient(x, cells, D)
    W = strain_energy(deformation_jets(F), p, frame)
    m = F.shape[0]
    P = W.g.reshape(m, 3, 3)  # first Piola stress dW/dF
    A = W.h.reshape(m, 3, 3, 3, 3)  # d2W/dF dF
    fe = -V0[:, None, None] * np.einsum("mki,mai->mak", P, D)
    Ke = V0[:, None, None, None, None] * np.einsum("mai,mkilj,mbj->makbl", D, A, D)
    return fe, Ke, float(np.sum(V0 * W.v))


# ----------------------------------------------------------------------------- output
def write_output(out, n, cells, fe, Ke, energy):
    m = cells.shape[0]
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)  # node-major: 3 a + c
    force = np.zeros(3 * n)
    np.add.at(force, dof.ravel(), fe.reshape(-1).astype(np.float64))
    force.astype("<f8").tofile(out / "force.f64")
    np.repeat(dof, 12, axis=1).astype("<i8").tofile(out / "stiffness_rows.i64")
    np.tile(dof, (1, 12)).astype("<i8").tofile(out / "stiffness_cols.i64")
    Ke.reshape(m, 144).astype("<f8").tofile(out / "stiffness_values.f64")
    if energy is not None:
        np.array([energy], dtype="<f8").tofile(out / "energy.f64")


def main(argv):
    if len(argv) != 3:
        raise SystemExit(__doc__)
    inp, out = Path(argv[1]), Path(argv[2])
    meta, arrays = read_case(inp)
    model = meta["model"]
    if model["kind"] != "material" or model["name"] != MATERIAL:
        raise SystemExit(f"this engine computes {MATERIAL}, not {model.get('name')}")
    p = {k: float(v) for k, v in model["parameters"].items()}
    X = arrays["points"].astype(REAL)
    x = arrays["positions"].astype(REAL)
    cells = arrays["cells"].astype(np.int64)
    frame = arrays["frame"].astype(REAL) if "frame" in arrays else None
    if frame is not None and frame.ndim == 2:
        frame = np.broadcast_to(frame, (cells.shape[0], 3, 3)).copy()
    fe, Ke, energy = element_terms(X, x, cells, p, frame)
    out.mkdir(parents=True, exist_ok=True)
    write_output(out, x.shape[0], cells, fe, Ke, energy)


if __name__ == "__main__":
    main(sys.argv)
