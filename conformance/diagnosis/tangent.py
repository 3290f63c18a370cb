"""Which part of the tangent (or of the volumetric energy) explains an error.

Two fits, both linear least squares whose residual is the evidence:

1. **Tangent parts.** The stiffness error D = K - K_o is fitted by c_1 P_1 (+ c_2 P_2) over the
   oracle's parts (:mod:`conformance.judge.parts`): geometric / material, volumetric / isochoric and
   the Voigt blocks of the material part. The smallest set of parts whose fit leaves less than
   the tolerance is named, with its coefficients (c = -1: part missing, c = +1: part doubled).
2. **Volumetric energy.** If the engine's J-only energy U differs from the oracle's, then per
   cell the force error is -V (dU) dJ/dx and the stiffness error V (dU'' dJ (x) dJ + dU' d2J),
   with two unknowns dU'(J_c), dU''(J_c) per cell. The fit over all cells (3n + nnz(K)
   equations, 2m unknowns) tests that hypothesis; when the state has several values of J the
   fitted dU'(J) is compared with the common variant k/2 (J - 1)^2 in place of k/2 (ln J)^2.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr
from scipy.sparse.linalg import norm as sparse_norm

from mjed.mesh import shape_vectors

__all__ = [
    "PartFit",
    "candidate_parts",
    "fit_parts",
    "VolumetricFit",
    "fit_volumetric",
    "describe_coefficient",
    "FiniteDifferenceFit",
    "fit_finite_difference",
    "step_fits",
]


@dataclass(frozen=True)
class PartFit:
    """names: the parts used; coefficients: c_i; residual: ||D - sum c_i P_i||_F / ||K_o||_F."""

    names: Tuple[str, ...]
    coefficients: Tuple[float, ...]
    residual: float


def candidate_parts(parts, K_o: sp.csr_matrix) -> Dict[str, sp.csr_matrix]:
    """Named parts from the oracle's split; zero parts are dropped."""
    G = parts["geometric"]
    out = {
        "geometric stiffness": G,
        "material stiffness": (K_o - G).tocsr(),
        "shear-shear block of the material tangent (Voigt)": parts["material_shear_shear"],
        "normal-shear blocks of the material tangent (Voigt)": parts["material_normal_shear"],
        "normal-normal block of the material tangent (Voigt)": parts["material_normal_normal"],
    }
    Gv, Mv = parts["geometric_volumetric"], parts["material_volumetric"]
    if Gv is not None and Mv is not None:
        out.update(
            {
                "volumetric tangent (J-only terms)": (Gv + Mv).tocsr(),
                "isochoric tangent (all but the J-only terms)": (K_o - Gv - Mv).tocsr(),
                "volumetric material tangent": Mv,
                "volumetric geometric stiffness": Gv,
                "isochoric material tangent": (K_o - G - Mv).tocsr(),
                "isochoric geometric stiffness": (G - Gv).tocsr(),
            }
        )
    nK = float(sparse_norm(K_o))
    return {k: v for k, v in out.items() if v is not None and float(sparse_norm(v)) > 1e-12 * nK}


def _gram(mats: Sequence[sp.csr_matrix]) -> np.ndarray:
    k = len(mats)
    G = np.empty((k, k))
    for i in range(k):
        for j in range(i, k):
            G[i, j] = G[j, i] = float(mats[i].multiply(mats[j]).sum())
    return G


def fit_parts(
    D: sp.csr_matrix,
    K_o: sp.csr_matrix,
    candidates: Dict[str, sp.csr_matrix],
    tol: float,
    max_parts: int = 2,
) -> Tuple[Optional[PartFit], Optional[PartFit]]:
    """(smallest fit within ``tol``, best fit found) over subsets of up to ``max_parts`` parts."""
    names = list(candidates)
    mats = [candidates[k] for k in names]
    G = _gram(mats)
    b = np.array([float(m.multiply(D).sum()) for m in mats])
    dd = float(D.multiply(D).sum())
    nK2 = float(K_o.multiply(K_o).sum())
    best: Optional[PartFit] = None
    # The Gram-matrix residual loses about half the digits to cancellation; it only shortlists,
    # and the shortlisted fits are recomputed from the matrices.
    shortlist = 1e-6 * np.sqrt(dd / nK2) + 10 * tol
    for size in range(1, max_parts + 1):
        exact = []
        for idx in itertools.combinations(range(len(names)), size):
            Gs = G[np.ix_(idx, idx)]
            if np.linalg.cond(Gs) > 1e12:
                continue  # two parts that coincide in this state: no fit can tell them apart
            c = np.linalg.solve(Gs, b[list(idx)])
            res2 = max(dd - 2 * c @ b[list(idx)] + c @ Gs @ c, 0.0)
            fit = PartFit(
                tuple(names[i] for i in idx), tuple(float(v) for v in c), float(np.sqrt(res2 / nK2))
            )
            if fit.residual <= shortlist:
                R = D - sum(ci * mats[i] for ci, i in zip(fit.coefficients, idx))
                fit = PartFit(fit.names, fit.coefficients, float(sparse_norm(R)) / np.sqrt(nK2))
                exact.append(fit)
            if best is None or fit.residual < best.residual:
                best = fit
        if exact:
            top = min(exact, key=lambda f: f.residual)
            if top.residual <= tol:
                return top, top
    return None, best


def describe_coefficient(name: str, c: float) -> str:
    for value, words in (
        (-1.0, "missing"),
        (1.0, "counted twice"),
        (-2.0, "with the wrong sign"),
        (-0.5, "halved"),  # a factor 2 lost (CC = 4 d2W/dC2 written with the stress's 2)
    ):
        if abs(c - value) < 1e-6:
            return f"{name} {words} (coefficient {c:+.6g})"
    return f"{name} scaled by {1 + c:.6g} (error coefficient {c:+.6g})"


# ------------------------------------------------------------------ volumetric energy
@dataclass(frozen=True)
class VolumetricFit:
    """Per-cell fit of the error as a different J-only energy.

    dU1, dU2: (m,) fitted dU'(J_c) and dU''(J_c) (engine minus oracle) [Pa];
    force_residual, stiffness_residual: relative errors left after the correction;
    J: (m,) the cells' volume ratios; variant: text naming a recognised variant, or "".
    """

    dU1: np.ndarray
    dU2: np.ndarray
    J: np.ndarray
    force_residual: float
    stiffness_residual: float
    variant: str = ""


def _cell_derivatives(points: np.ndarray, cells: np.ndarray, x: np.ndarray):
    """V0 (m,), J (m,), dJ/dx (m, 12) and d2J/dx2 (m, 12, 12) per cell (node-major local dofs)."""
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    J = np.linalg.det(F)
    g = np.einsum("mji,maj->mai", np.linalg.inv(F), D)  # F^-T D_a: (m, 4, 3)
    dJ = (J[:, None, None] * g).reshape(-1, 12)
    # d2J/dx_ai dx_bj = J (g_ai g_bj - g_bi g_aj)
    H = J[:, None, None, None, None] * (
        np.einsum("mai,mbj->maibj", g, g) - np.einsum("mbi,maj->maibj", g, g)
    )
    return V0, J, dJ, H.reshape(-1, 12, 12)


def fit_volumetric(
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    df: np.ndarray,
    D: sp.csr_matrix,
    force_scale: float,
    stiffness_scale: float,
) -> Optional[VolumetricFit]:
    """Fit the errors (df (n, 3), D (3n, 3n)) as a per-cell change of the J-only energy."""
    m, n = cells.shape[0], points.shape[0]
    N = 3 * n
    V0, J, dJ, H = _cell_derivatives(points, cells, x)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    # Stiffness pattern: every (row, col) of every cell block, numbered once.
    rows = np.repeat(dofs, 12, axis=1)
    cols = np.tile(dofs, (1, 12))
    keys = rows.astype(np.int64) * N + cols
    pattern, where = np.unique(keys.ravel(), return_inverse=True)
    where = where.reshape(m, 144)
    n_eq = N + pattern.size
    cell = np.arange(m)
    # Column 2c: dU'' -> K gets V dJ (x) dJ. Column 2c+1: dU' -> force -V dJ, K V d2J.
    outer = (V0[:, None, None] * dJ[:, :, None] * dJ[:, None, :]).reshape(m, 144) / stiffness_scale
    hess = (V0[:, None, None] * H).reshape(m, 144) / stiffness_scale
    force_col = (-V0[:, None] * dJ) / force_scale
    A = sp.coo_matrix(
        (
            np.concatenate([outer.ravel(), hess.ravel(), force_col.ravel()]),
            (
                np.concatenate([N + where.ravel(), N + where.ravel(), dofs.ravel()]),
                np.concatenate(
                    [
                        np.repeat(2 * cell, 144),
                        np.repeat(2 * cell + 1, 144),
                        np.repeat(2 * cell + 1, 12),
                    ]
                ),
            ),
        ),
        shape=(n_eq, 2 * m),
    ).tocsr()
    Dc = sp.coo_matrix(D)
    dkeys = Dc.row.astype(np.int64) * N + Dc.col
    pos = np.searchsorted(pattern, dkeys)
    inside = (pos < pattern.size) & (pattern[np.minimum(pos, pattern.size - 1)] == dkeys)
    b = np.zeros(n_eq)
    b[:N] = df.ravel() / force_scale
    np.add.at(b, N + pos[inside], Dc.data[inside] / stiffness_scale)
    outside = (
        float(np.linalg.norm(Dc.data[~inside])) / stiffness_scale
    )  # error where no cell couples: unfittable
    # Least squares by LSQR on unit-norm columns (a direct factorisation of the normal equations
    # fills in badly on large meshes). Stopping far below the tolerance keeps the residual honest.
    norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    norms[norms == 0] = 1.0
    As = A @ sp.diags(1.0 / norms)
    sol = lsqr(As, b, atol=1e-15, btol=1e-15, iter_lim=20 * 2 * m)
    c = sol[0] / norms
    r = A @ c - b
    fres = float(np.linalg.norm(r[:N]))
    kres = float(np.hypot(np.linalg.norm(r[N:]), outside))
    dU2, dU1 = c[0::2], c[1::2]
    return VolumetricFit(dU1, dU2, J, fres, kres, _variant(J, dU1))


def _variant(J: np.ndarray, dU1: np.ndarray) -> str:
    """Recognise k/2 (J - 1)^2 used instead of k/2 (ln J)^2: dU' = k ((J - 1) - ln J / J)."""
    distinct = np.unique(np.round(J, 12))
    if distinct.size < 3:
        return ""
    basis = (J - 1.0) - np.log(J) / J
    bb = float(basis @ basis)
    if bb == 0 or not np.any(dU1):
        return ""
    k = float(basis @ dU1) / bb
    rel = float(np.linalg.norm(dU1 - k * basis) / np.linalg.norm(dU1))
    if rel < 1e-6:
        return (
            f"k/2 (J-1)^2 used for the bulk term instead of k/2 (ln J)^2, k = {k:.6g} Pa (fit over "
            f"{distinct.size} distinct J values, relative residual {rel:.1e})"
        )
    return ""


# ------------------------------------------------------------------ finite-difference tangent
def step_fits(B: sp.csr_matrix, D: sp.csr_matrix, order: int):
    """The one-unknown fits of D = c B (B the leading error of a difference scheme per unit
    step^order: order 1 forward or backward, order 2 central), B as is and symmetrised: yields
    (symmetrised, scheme, step, ||D - c B||, c B). Of order 2, c > 0 is central differences
    (error + h^2/6 times the force's third derivative) and c < 0 a complex step,
    Im f(x + i h e_j) / h, whose truncation error is the same term with the other sign.
    """
    for symmetrised in (False, True):
        Bs = (0.5 * (B + B.T)).tocsr() if symmetrised else B
        bb = float(Bs.multiply(Bs).sum())
        if bb == 0.0:
            continue
        c = float(Bs.multiply(D).sum()) / bb
        if order == 2 and c == 0:
            continue
        step = abs(c) if order == 1 else float(np.sqrt(abs(c)))
        if order == 2:
            scheme = "central" if c > 0 else "complex step"
        else:
            scheme = "forward" if c > 0 else "backward"
        yield symmetrised, scheme, step, float(sparse_norm(D - c * Bs)), (c * Bs).tocsr()


@dataclass(frozen=True)
class FiniteDifferenceFit:
    """A stiffness built from differences of the force, as fitted.

    scheme: "forward", "backward" or "central"; rule: "absolute" (h_j = h), "relative"
    (h_j = eps |x_j|) or "relative, at least eps" (h_j = eps max(|x_j|, 1)); symmetrised: the
    differences' matrix symmetrised ((K + K^T) / 2) before it was written; step: h [m] or eps
    (dimensionless) of the rule; explained: the fraction of ||K - K_o||_F the fit accounts for;
    residual: what is left, relative to ||K_o||_F.
    """

    scheme: str
    rule: str
    symmetrised: bool
    step: float
    explained: float
    residual: float

    def words(self) -> str:
        h = {
            "absolute": f"a step h = {self.step:.2e} m",
            "relative": f"a relative step h_j = {self.step:.2e} |x_j|",
            "relative, at least eps": f"a step h_j = {self.step:.2e} max(|x_j|, 1)",
        }[self.rule]
        sym = ", then symmetrised" if self.symmetrised else ""
        if self.scheme == "complex step":
            return (
                f"a complex step, Im f(x + i h_j e_j) / h_j, with {h}{sym}: the step too large "
                "(what is left is its truncation error, - h^2/6 of the force's third derivative)"
            )
        return f"{self.scheme} differences of the force with {h}{sym}"


#: The step rules: name -> weight of column j from the coordinate x_j.
_RULES = {
    "absolute": lambda x: np.ones_like(x),
    "relative": np.abs,
    "relative, at least eps": lambda x: np.maximum(np.abs(x), 1.0),
}


def fit_finite_difference(
    D: sp.csr_matrix, G1: sp.csr_matrix, G2: sp.csr_matrix, K_o: sp.csr_matrix, x: np.ndarray
) -> Optional[FiniteDifferenceFit]:
    """The scheme, step rule and step that best explain D = K - K_o as a tangent built column by
    column from differences of the force:

    - forward (backward: a negative step): -(f(x + h_j e_j) - f(x)) / h_j = K e_j
      + (h_j / 2) G1 e_j + O(h^2), G1 e_j the derivative of K's column j along dof j;
    - central: -(f(x + h_j e_j) - f(x - h_j e_j)) / (2 h_j) = K e_j + (h_j^2 / 6) G2 e_j + O(h^4),
      G2 e_j the second derivative of K's column j along dof j;

    h_j by each rule of :data:`_RULES`, with or without the matrix symmetrised afterwards. Each
    candidate has one unknown (h or eps), fitted by least squares: the figure that explains most
    of D is returned. D, G1, G2, K_o: (3n, 3n); x: (3n,) the positions. None when D is zero or
    the energy has no third derivative.
    """
    nD = float(sparse_norm(D))
    if nD == 0.0 or float(sparse_norm(G1)) == 0.0:
        return None
    best: Optional[FiniteDifferenceFit] = None
    for G, order in ((G1, 1), (G2, 2)):
        for rule, weight in _RULES.items():
            w = weight(np.asarray(x, dtype=np.float64).ravel()) ** order
            B = (G @ sp.diags(w / (2.0 if order == 1 else 6.0))).tocsr()
            for symmetrised, name, step, left, _ in step_fits(B, D, order):
                fit = FiniteDifferenceFit(
                    name,
                    rule,
                    symmetrised,
                    step,
                    1.0 - left / nD,
                    left / float(sparse_norm(K_o)),
                )
                if best is None or fit.explained > best.explained + 1e-12:
                    best = fit
    return best
