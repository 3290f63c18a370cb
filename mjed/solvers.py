"""Linear solvers of the implicit schemes: preconditioned conjugate gradients and an SPD factor.

CG is written out (rather than scipy.sparse.linalg.cg) so that a loss of positive
definiteness is detected and reported: CG on an indefinite matrix can "converge" to nonsense or
stall, and a verification suite must say which happened.

Preconditioners are callables r (N,) -> z (N,) applying an SPD approximation of A^-1:

- ``jacobi_preconditioner``: 1 / diag(A) (the default; SOFA's CG is unpreconditioned or Jacobi);
- ``block_jacobi_preconditioner``: the inverse of A's 3x3 node blocks;
- ``SPDFactor``: a sparse factorisation of an SPD matrix, exact for the matrix it factors and,
  kept over several time steps, a close preconditioner of the matrices that follow (the
  integrator's "factorized" option).

``SPDFactor`` also certifies positive definiteness: SuperLU is asked for a symmetric
fill-reducing ordering and diagonal pivots only, so for a symmetric A the factorisation is
P A P^T = L U with U = D L^T and, by Sylvester's law of inertia, A is positive definite exactly
when every pivot in D is positive. A non-positive pivot raises :class:`NotPositiveDefiniteError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = [
    "LinearSolverOptions",
    "LINEAR_SOLVERS",
    "PRECONDITIONERS",
    "FACTOR_PRECISIONS",
    "CGResult",
    "NotPositiveDefiniteError",
    "SPDFactor",
    "block_jacobi_preconditioner",
    "conjugate_gradient",
    "jacobi_preconditioner",
]

Preconditioner = Callable[[np.ndarray], np.ndarray]

#: Linear solvers, CG preconditioners and factorisation precisions of LinearSolverOptions.
LINEAR_SOLVERS = ("cg", "direct", "cuda-cg")
PRECONDITIONERS = ("jacobi", "block-jacobi", "factorized")
FACTOR_PRECISIONS = ("double", "single")


@dataclass(frozen=True)
class LinearSolverOptions:
    """How an implicit scheme solves its linear system each step (validated on construction).

    - solver: "cg" (preconditioned conjugate gradients), "direct" (a sparse factorisation of
      every system; its residual is still held to ``cg_tol``) or "cuda-cg" (Jacobi CG on an
      NVIDIA GPU, :func:`mjed.cuda.solvers.device_conjugate_gradient`: the system is copied
      to the device at each solve; needs the "jacobi" preconditioner, Numba's CUDA target and
      a device).
    - cg_tol: relative residual ||b - A x|| / ||b|| to reach, > 0.
    - max_iterations: CG's iteration cap, an integer >= 1.
    - preconditioner: "jacobi", "block-jacobi" or "factorized" (a kept sparse factorisation
      of an earlier system, see mjed.integrator), for "cg" only.
    - refactor_iterations: with "factorized", a solve needing more CG iterations than this
      renews the factorisation at the next solve.
    - factor_precision: "double" or "single" precision of the "factorized" preconditioner's
      factorisation (the direct solver always factorises in double precision).

    Raises:
        ValueError: naming the field and the accepted values.
    """

    solver: str = "cg"
    cg_tol: float = 1e-8
    max_iterations: int = 1000
    preconditioner: str = "jacobi"
    refactor_iterations: int = 20
    factor_precision: str = "double"

    def __post_init__(self) -> None:
        for name, allowed in (
            ("solver", LINEAR_SOLVERS),
            ("preconditioner", PRECONDITIONERS),
            ("factor_precision", FACTOR_PRECISIONS),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(
                    f"LinearSolverOptions.{name} must be one of {allowed}, got "
                    f"{getattr(self, name)!r}"
                )
        if self.solver == "cuda-cg" and self.preconditioner != "jacobi":
            raise ValueError(
                "LinearSolverOptions.solver='cuda-cg' runs the 'jacobi' preconditioner only, got "
                f"preconditioner={self.preconditioner!r}"
            )
        tol = self.cg_tol
        if (
            isinstance(tol, bool)
            or not isinstance(tol, (int, float))
            or not (math.isfinite(tol) and tol > 0)
        ):
            raise ValueError(f"LinearSolverOptions.cg_tol must be finite and > 0, got {tol!r}")
        object.__setattr__(self, "cg_tol", float(tol))
        for name in ("max_iterations", "refactor_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"LinearSolverOptions.{name} must be an integer >= 1, got {v!r}")
            object.__setattr__(self, name, int(v))

    def label(self) -> str:
        """One line for tables: how each system was solved."""
        if self.solver == "direct":
            return f"direct sparse LU (SuperLU) every solve, residual <= {self.cg_tol:g}"
        if self.solver == "cuda-cg":
            return f"CG on the GPU, jacobi preconditioner, rtol {self.cg_tol:g}"
        if self.preconditioner == "factorized":
            return (
                f"CG, kept {self.factor_precision}-precision sparse LU preconditioner (renewed "
                f"after > {self.refactor_iterations} iterations), rtol {self.cg_tol:g}"
            )
        return f"CG, {self.preconditioner} preconditioner, rtol {self.cg_tol:g}"


@dataclass(frozen=True)
class CGResult:
    """x: the solution (or last iterate); iterations; converged; reason: "converged",
    "max_iterations", "negative_curvature" (p^T A p <= 0: A is not positive definite),
    "preconditioner_indefinite" (r^T z <= 0: the preconditioner is not positive definite) or
    "non_finite"; residual: final ||b - A x|| / ||b||.
    """

    x: np.ndarray
    iterations: int
    converged: bool
    reason: str
    residual: float


class NotPositiveDefiniteError(ValueError):
    """A factorisation met non-positive pivots: the matrix is not symmetric positive definite.

    Attributes: n_negative (pivots <= 0), n (the matrix size).
    """

    def __init__(self, n_negative: int, n: int, detail: str = ""):
        self.n_negative, self.n = int(n_negative), int(n)
        super().__init__(
            f"the matrix is not positive definite: {n_negative} of its {n} pivots are <= 0{detail}"
        )


def jacobi_preconditioner(A) -> Preconditioner:
    """Z = r / diag(A); a non-positive diagonal entry is replaced by 1 (keeps z SPD in r)."""
    d = np.asarray(A.diagonal(), dtype=float)
    inv_d = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 1.0)
    return lambda r: inv_d * r


def block_jacobi_preconditioner(A, block: int = 3) -> Preconditioner:
    """Z = blockdiag(A)^-1 r with consecutive ``block`` x ``block`` diagonal blocks (the 3x3
    node blocks of a dof = 3 node + component system whose constraints remove whole nodes).

    A block that is not positive definite is replaced by the Jacobi scaling of its diagonal
    (as jacobi_preconditioner does), so the preconditioner stays SPD.

    Raises:
        ValueError: the size of A is not a multiple of ``block``.
    """
    n = A.shape[0]
    if n % block:
        raise ValueError(
            f"block_jacobi_preconditioner: size {n} is not a multiple of the block size {block}"
        )
    k = n // block
    rows = np.arange(n)
    # Entries (i, j) of each diagonal block, gathered from the sparse matrix in one go.
    first = (rows // block) * block
    i = np.repeat(rows, block)
    j = (first[:, None] + np.arange(block)).ravel()
    blocks = np.asarray(sp.csr_matrix(A)[i, j]).reshape(k, block, block)
    blocks = 0.5 * (blocks + np.swapaxes(blocks, 1, 2))
    eig = np.linalg.eigvalsh(blocks)
    good = np.isfinite(eig).all(axis=1) & (eig[:, 0] > 0)
    inv = np.zeros_like(blocks)
    inv[good] = np.linalg.inv(blocks[good])
    if not good.all():
        d = np.diagonal(blocks[~good], axis1=1, axis2=2)
        inv[~good] = np.eye(block) * np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 1.0)[:, :, None]
    return lambda r: (inv @ r.reshape(k, block, 1)).reshape(n)


class SPDFactor:
    """Sparse factorisation of a symmetric positive definite matrix (SuperLU, symmetric mode).

    Args:
        A: (N, N) sparse symmetric matrix.
        single: factorise in single precision (about half the time; a preconditioner needs no
            more, since it only has to approximate A^-1: CG's own arithmetic stays double). The
            pivot signs are then those of the rounded matrix: for an ill-conditioned A, retry
            in double precision before concluding that A is not positive definite.

    Raises:
        NotPositiveDefiniteError: a pivot <= 0 (or SuperLU found A singular).

    Calling the object solves A x = b for b (N,) (in the factor's precision, returning float64);
    it serves as a CG preconditioner.
    """

    def __init__(self, A, *, single: bool = False):
        self.dtype = np.float32 if single else np.float64
        A = sp.csc_matrix(A, dtype=self.dtype)
        n = A.shape[0]
        self.n = n
        try:
            # Symmetric (A + A^T) minimum-degree ordering applied to rows and columns, diagonal
            # pivots only: U = D L^T, the pivots are D.
            lu = spla.splu(
                A,
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options=dict(SymmetricMode=True),
            )
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise NotPositiveDefiniteError(1, n, f" (SuperLU: {exc})") from None
        pivots = lu.U.diagonal()
        if not np.array_equal(lu.perm_r, lu.perm_c):  # SuperLU swapped rows: no inertia certificate
            raise NotPositiveDefiniteError(1, n, " (SuperLU had to pivot off the diagonal)")
        bad = int(np.count_nonzero(~(pivots > 0)))
        if bad:
            raise NotPositiveDefiniteError(bad, n)
        self._lu = lu
        self.fill = int(lu.L.nnz + lu.U.nnz)

    def __call__(self, b: np.ndarray) -> np.ndarray:
        if self.dtype is np.float64:
            return self._lu.solve(b)
        return self._lu.solve(np.asarray(b, dtype=self.dtype)).astype(np.float64)


def conjugate_gradient(
    A,
    b: np.ndarray,
    *,
    tol: float = 1e-10,
    max_iterations: int = 1000,
    x0=None,
    preconditioner: Optional[Preconditioner] = None,
) -> CGResult:
    """Solve A x = b for a symmetric A by preconditioned CG.

    Args:
        A: (N, N) sparse or dense symmetric matrix.
        b: (N,).
        tol: relative residual ||r|| / ||b|| to reach.
        x0: first guess (N,) (zero by default); returned as is if it already meets tol.
        preconditioner: r -> z, an SPD approximation of A^-1; default Jacobi (1 / diag(A)).
    """
    b = np.asarray(b, dtype=float)
    nb = math.sqrt(float(b @ b))
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    if nb == 0.0:
        return CGResult(x, 0, True, "converged", 0.0)
    apply = jacobi_preconditioner(A) if preconditioner is None else preconditioner
    r = b - A @ x if x0 is not None else b.copy()
    res = math.sqrt(float(r @ r)) / nb
    if res <= tol:
        return CGResult(x, 0, True, "converged", res)
    z = apply(r)
    rz = float(r @ z)
    p = z.copy()
    for k in range(1, max_iterations + 1):
        if not (rz > 0.0):
            reason = "non_finite" if not math.isfinite(rz) else "preconditioner_indefinite"
            return CGResult(x, k, False, reason, res)
        Ap = A @ p
        pAp = float(p @ Ap)
        if not math.isfinite(pAp):
            return CGResult(x, k, False, "non_finite", res)
        if pAp <= 0.0:
            return CGResult(x, k, False, "negative_curvature", res)
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        res = math.sqrt(float(r @ r)) / nb
        if res <= tol:
            return CGResult(x, k, True, "converged", res)
        z = apply(r)
        rz_new = float(r @ z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return CGResult(x, max_iterations, False, "max_iterations", res)
