"""Test engines whose energy is an unusual function of F, differentiated exactly in NumPy.

Some tests need an engine that computes a *different* energy from the oracle's (Costa with F
transposed, with its frame pushed forward, with a Gram-Schmidt frame) to see that the check
names it. Handing such an energy to the UFL oracle costs a compiled form per energy, and the
stiffness form of a frame rebuilt from F is among the largest FFCx ever writes here (over a
minute to generate and compile on a fresh machine). These engines instead evaluate the energy
density with hyper-dual numbers (a + b e1 + c e2 + d e1 e2, e1^2 = e2^2 = 0): seeded along two
components of F, one evaluation gives the density, dW/dF and d2W/dF2 exactly, to round-off, with
no step to choose. The density is written against the project's formula namespace (the same
quantities C, E, J, I1b, ... a declared material's formula uses), here bound to hyper-dual
arrays vectorised over the cells and the 81 pairs of components of F.

:func:`density_engine` turns a density W(k, F) into an engine ``case -> (f, K, W)`` on P1
tetrahedra: f_ai = -V0 P_ik D_ak, K_ai,bj = V0 A_ikjl D_ak D_bl (P = dW/dF, A = d2W/dF2, D_a the
reference shape gradients, V0 the reference volume), nodes major in the dofs (3 a + i), the
force with the convention's sign: f = -dW/dx.
"""

from __future__ import annotations

from typing import Any, Callable, Tuple

import numpy as np
import scipy.sparse as sp

from common.hyperdual import HD, exp, ln, sqrt

__all__ = ["HD", "Matrix", "Namespace", "density_engine", "hyperdual_F"]


class Matrix:
    """A 3x3 matrix of hyper-dual (or plain) entries with the formula namespace's meaning of
    ``*`` (matrix product with a Matrix, scaling otherwise), ``.T``, ``+``, ``-``, ``[i, j]``.
    """

    def __init__(self, rows):
        self.rows = [list(r) for r in rows]

    @staticmethod
    def identity() -> "Matrix":
        return Matrix([[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)])

    def __getitem__(self, ij):
        i, j = ij
        return self.rows[i][j]

    @property
    def T(self) -> "Matrix":
        return Matrix([[self.rows[j][i] for j in range(3)] for i in range(3)])

    def column(self, j: int) -> list:
        return [self.rows[i][j] for i in range(3)]

    def __add__(self, o: "Matrix") -> "Matrix":
        return Matrix([[self[i, j] + o[i, j] for j in range(3)] for i in range(3)])

    def __sub__(self, o: "Matrix") -> "Matrix":
        return Matrix([[self[i, j] - o[i, j] for j in range(3)] for i in range(3)])

    def __mul__(self, o):
        if isinstance(o, Matrix):
            return Matrix(
                [[sum(self[i, k] * o[k, j] for k in range(3)) for j in range(3)] for i in range(3)]
            )
        return Matrix([[self[i, j] * o for j in range(3)] for i in range(3)])

    __rmul__ = __mul__

    def times_vector(self, v: list) -> list:
        return [sum(self[i, k] * v[k] for k in range(3)) for i in range(3)]


def det(F: Matrix):
    return (
        F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
        - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
        + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0])
    )


def tr(A: Matrix):
    return A[0, 0] + A[1, 1] + A[2, 2]


class Namespace:
    """The formula namespace (mjed.materials.declaration.FormulaNamespace) bound to hyper-dual
    entries: the quantities of docs/conventions.md, "Kinematics", for a deformation gradient F
    and a frame R (a Matrix; the identity when None).
    """

    exp = staticmethod(exp)
    ln = staticmethod(ln)
    tr = staticmethod(tr)

    def __init__(self, F: Matrix, frame: Any = None):
        self.C = F.T * F
        self.E = 0.5 * (self.C - Matrix.identity())
        self.I1 = tr(self.C)
        self.I2 = 0.5 * (self.I1 * self.I1 - tr(self.C * self.C))
        self.J = det(F)
        self.lnJ = ln(self.J)
        self.I1b = self.J ** (-2.0 / 3.0) * self.I1
        self.I2b = self.J ** (-4.0 / 3.0) * self.I2
        self.frame = Matrix.identity() if frame is None else frame

    @staticmethod
    def eigenvalue_power_sum(C, q):
        raise NotImplementedError("eigenvalues of C are not taken in hyper-dual arithmetic here")


def _pairs() -> Tuple[np.ndarray, np.ndarray]:
    """The 81 pairs (r, s) of components of F (r = 3 i + k for F_ik), r slowest."""
    r, s = np.divmod(np.arange(81), 9)
    return r, s


def hyperdual_F(F: np.ndarray) -> Matrix:
    """F (m, 3, 3) as a Matrix of hyper-dual (m, 81) arrays: pair p = (r, s) seeds e1 along
    component r and e2 along component s, so the result's d part at p is d2W/dF_r dF_s and its
    b part dW/dF_r.
    """
    r, s = _pairs()
    m = F.shape[0]
    zero = np.zeros((m, 81))
    rows = []
    for i in range(3):
        row = []
        for k in range(3):
            comp = 3 * i + k
            a = np.repeat(F[:, i, k][:, None], 81, axis=1)
            row.append(HD(a, (r == comp) + zero, (s == comp) + zero, zero))
        rows.append(row)
    return Matrix(rows)


def _constant_frame(R: np.ndarray) -> Matrix:
    """Per-cell frames (m, 3, 3) as a Matrix of (m, 1) arrays (no derivative parts)."""
    return Matrix([[R[:, i, j][:, None] for j in range(3)] for i in range(3)])


def _geometry(points: np.ndarray, cells: np.ndarray):
    """Reference shape gradients D (m, 4, 3) (row a = grad N_a) and volumes V0 (m,)."""
    X = points[cells]  # (m, 4, 3)
    edges = (X[:, 1:] - X[:, :1]).transpose(0, 2, 1)  # columns X_b - X_0
    inv = np.linalg.inv(edges)  # rows: gradients of N_1..N_3
    D = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)
    return D, np.abs(np.linalg.det(edges)) / 6.0


Density = Callable[[Any, Namespace, Matrix, Matrix], Any]


def density_engine(
    density: Density,
    frame_of: Callable[[Any], Any] = lambda model: None,
    gradients: Callable[[np.ndarray], np.ndarray] = lambda D: D,
    deformation: Callable[[np.ndarray], np.ndarray] = lambda F: F,
):
    """An engine ``case -> (f, K, W)`` for the energy density ``density(model, k, F, R)`` (the
    case's model, k the namespace at F, F the hyper-dual deformation gradient, R the cells'
    frames as a Matrix or None), per unit reference volume, on the case's P1 mesh;
    ``frame_of(model)`` gives the per-cell frames (m, 3, 3) or None (the identity);
    ``gradients(D)`` the shape gradients (m, 4, 3) the engine uses for F, force and matrix in
    place of the right ones D (a mistake's); ``deformation(F)`` the deformation gradient it
    forms from F = sum_a x_a D_a^T (a mistake's, e.g. I + F; its derivative in x is F's). The
    force is -dW/dx (docs/conventions.md, "Signs"), the stiffness d2W/dx2.
    """

    def engine(case):
        points, cells = np.asarray(case.points, float), np.asarray(case.cells)
        D, V0 = _geometry(points, cells)
        D = gradients(D)
        x = np.asarray(case.positions, float).reshape(-1, 3)
        F = deformation(np.einsum("mai,mak->mik", x[cells], D))
        R = frame_of(case.model)
        if R is not None:
            R = np.broadcast_to(np.asarray(R, float), (len(cells), 3, 3))
            R = _constant_frame(R)
        Fh = hyperdual_F(F)
        W = density(case.model, Namespace(Fh, R), Fh, R)
        P = W.b[:, ::9].reshape(-1, 3, 3)  # the pairs (r, 0): dW/dF_r
        A = W.d.reshape(-1, 3, 3, 3, 3)  # d2W / dF_ik dF_jl
        f = np.zeros_like(x)
        np.add.at(f, cells, -np.einsum("m,mik,mak->mai", V0, P, D))
        Ke = np.einsum("m,mikjl,mak,mbl->maibj", V0, A, D, D).reshape(len(cells), 12, 12)
        dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12)
        n = x.size
        K = sp.coo_matrix(
            (Ke.ravel(), (np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel())),
            shape=(n, n),
        ).tocsr()
        return f.ravel(), K, float(np.dot(V0, W.a[:, 0]))

    return engine


def _unit(v: list) -> list:
    norm = sqrt(sum(c * c for c in v))
    return [c / norm for c in v]


def _cross(u: list, v: list) -> list:
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def pushed_frame(F: Matrix, R: Matrix) -> Matrix:
    """F R with each column normalised (the frame pushed forward, not re-orthogonalised)."""
    cols = [_unit(F.times_vector(R.column(j))) for j in range(3)]
    return Matrix([[cols[j][i] for j in range(3)] for i in range(3)])


def gram_schmidt_frame(F: Matrix, R: Matrix) -> Matrix:
    """The frame pushed forward and re-orthonormalised: fibre f = F R_0 / |F R_0|, sheet the
    part of F R_1 orthogonal to f, normalised, normal f x s.
    """
    f = _unit(F.times_vector(R.column(0)))
    b = F.times_vector(R.column(1))
    along = sum(f[i] * b[i] for i in range(3))
    s = _unit([b[i] - f[i] * along for i in range(3)])
    n = _cross(f, s)
    return Matrix([[f[i], s[i], n[i]] for i in range(3)])
