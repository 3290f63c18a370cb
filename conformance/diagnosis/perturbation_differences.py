"""A spatial tangent built by Miehe's perturbation of F, with one-sided differences.

An updated-Lagrangian engine that computes its spatial tangent column by column as

    c e_kl = (tau(F + eps E_kl F) - tau(F)) / (J eps) - (the Jaumann rate's terms),

E_kl = sym(e_k e_l) (Miehe 1996; the usual way to a UMAT's DDSDDE), has in column kl the error
(eps / 2) tau''_kl / J + O(eps^2), tau''_kl the second derivative of the Kirchhoff stress along
the path F(t) = (I + t E_kl) F. This is another error than that of differences of S in the
strain (:mod:`conformance.diagnosis.strain_differences`), so it is tested on its own: tau''
per cell by second differences of the oracle's stress (MJED's element forces on the mesh with
its cells pulled apart, each cell's F moved along the path), the stiffness v B^T c_lead B of
the leading error assembled (B from grad N = D F^-1, v = J V0), and eps fitted with one
unknown (forward: eps > 0, backward: eps < 0) by
:func:`conformance.diagnosis.strain_differences.strain_difference_reading`, beside the strain
scheme: named, as partly explaining, when the fit accounts for nearly all of the stiffness error
(99 %), as the other difference readings are; both fitting are said as ambiguous.

**The perturbation itself wrong.** In the limit of a small step a numerical column is the
directional derivative of the differenced stress along the perturbation, so each scheme of
:data:`SCHEMES` (the perturbation unsymmetrised, e_k e_l F, whose skew part is a spin; the shear
step doubled or halved; F not multiplied on the right, or multiplied on the left; the Cauchy
stress differenced; the division by J left out) predicts the engine's tangent per cell from the
oracle's first elasticity tensor A = dP/dF (read back from its element matrices:
tau'[M] = (A : M) F^T + P M^T), nothing fitted; the driver's removal of the Jaumann terms is the
same as the right scheme's. What the step leaves, (eps / 2) Q''[M, M] / J + O(eps^2) in each
column (Q'' the second derivative of the differenced stress along the scheme's own path, from
the oracle by second differences, as for Miehe's), is fitted with one unknown, eps.
:func:`scheme_findings` names a scheme (read by
:func:`conformance.diagnosis.strain_differences.strain_difference_reading` when neither
difference scheme with the right perturbation fits) when its prediction with the fitted step
leaves the stiffness within the tolerance or, beyond it, below sqrt(u) of the oracle's stiffness
(the round-off of differences at a step of sqrt(u) or more,
:data:`conformance.diagnosis.spatial_variants.NUMERICAL`), while the right scheme (Miehe's) with
its own fitted step does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola
from conformance.diagnosis.spatial_variants import FEBIO, U, from_voigt, jaumann_terms

__all__ = [
    "STEP",
    "SCHEMES",
    "stress_curvatures",
    "kirchhoff_curvatures",
    "perturbation_basis",
    "piola_basis",
    "scheme_directions",
    "scheme_tangent",
    "scheme_findings",
]

#: Step of the second differences of tau along the path (dimensionless, like eps).
STEP = 1e-3


def _sym_unit(k: int, l: int) -> np.ndarray:  # noqa: E741 - the index names of the formula
    """(3, 3) E_kl = (e_k e_l^T + e_l e_k^T) / 2."""
    E = np.zeros((3, 3))
    E[k, l] += 0.5
    E[l, k] += 0.5
    return E


def stress_curvatures(
    model: Any, split: ElementSplit, points: np.ndarray, directions: np.ndarray, quantity: str
) -> Optional[np.ndarray]:
    """(m, k, 3, 3) per cell Q'' along each of the k directions M (m, k, 3, 3) per unit step:
    the second derivative of the oracle's stress Q along F + t M, by second differences of
    MJED's element forces on the mesh with its cells pulled apart; quantity: "tau" (divided by
    the cell's J), "cauchy" (sigma), "tau-no-J" (tau) or "piola" (P); None when MJED cannot
    evaluate the model there.
    """
    import mjed

    cells, F = split.cells, split.F
    m = cells.shape[0]
    X = points[cells]
    loose = np.arange(4 * m).reshape(m, 4)
    Xc = X - X[:, :1]
    J = np.linalg.det(F)
    Dp = np.linalg.pinv(split.D)  # (m, 3, 4): P from the element forces, f_a = -V0 P D_a

    def stress(field, Fs: np.ndarray) -> np.ndarray:
        """(m, 3, 3) the oracle's Q at per-cell gradients Fs, over the scheme's divisor."""
        xs = (np.einsum("mij,maj->mai", Fs, Xc) + X[:, :1]).reshape(-1, 3)
        fe = np.asarray(field.element_forces(xs), dtype=np.float64)
        P = -np.einsum("mja,mak->mkj", Dp, fe) / split.V0[:, None, None]
        if quantity == "piola":
            return P
        tau = P @ Fs.swapaxes(1, 2)
        if quantity == "cauchy":
            return tau / np.linalg.det(Fs)[:, None, None]
        return tau if quantity == "tau-no-J" else tau / J[:, None, None]

    out = np.empty(directions.shape)
    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), loose), model)
        t0 = stress(field, F)
        for col in range(directions.shape[1]):
            step = STEP * directions[:, col]
            out[:, col] = (stress(field, F + step) + stress(field, F - step) - 2.0 * t0) / STEP**2
    except Exception:  # noqa: BLE001 - not an MJED material, or an inverted moved cell
        return None
    return out


def kirchhoff_curvatures(
    model: Any,
    split: ElementSplit,
    points: np.ndarray,
    directions: Optional[np.ndarray] = None,
    quantity: str = "tau",
) -> Optional[np.ndarray]:
    """(m, 6, 6) per cell Q''_kl / J in Voigt form: row I the pair I of Q'' (the second
    derivative of the stress Q along F + t M_kl), column the perturbation kl (both in FEBio
    order); directions: (m, 6, 3, 3) M_kl per unit step (default Miehe's sym(e_k e_l) F);
    quantity: "tau" (divided by J), "cauchy" (sigma, not divided) or "tau-no-J" (tau, not
    divided), as :data:`SCHEMES`; None when MJED cannot evaluate the model there.
    """
    if directions is None:
        directions = scheme_directions("miehe", split.F)
    d2 = stress_curvatures(model, split, points, directions, quantity)
    if d2 is None:
        return None
    rows = np.array(FEBIO)
    return d2[:, :, rows[:, 0], rows[:, 1]].swapaxes(1, 2)


def piola_basis(model: Any, split: ElementSplit, points: np.ndarray) -> Optional[sp.csr_matrix]:
    """(3n, 3n) the assembled V0 D_aI dA_kIlL D_bL of the leading error per unit step of a
    first elasticity tensor A = dP/dF by one-sided differences of P in each component F_lL,
    dA_kIlL = (1/2) d2P_kI / dF_lL^2 (:func:`stress_curvatures` along e_l e_L); None when MJED
    cannot evaluate the model there.
    """
    m = split.F.shape[0]
    units = np.broadcast_to(np.eye(9).reshape(9, 3, 3), (m, 9, 3, 3))
    d2 = stress_curvatures(model, split, points, units, "piola")
    if d2 is None or not np.all(np.isfinite(d2)):
        return None
    dA = 0.5 * d2.reshape(m, 3, 3, 3, 3).transpose(0, 3, 4, 1, 2)  # [m, k, I, l, L]
    Ke = np.einsum("m,maI,mkIlL,mbL->makbl", split.V0, split.D, dA, split.D, optimize=True)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


def perturbation_basis(split: ElementSplit, curv: np.ndarray) -> sp.csr_matrix:
    """(3n, 3n) the assembled v B^T c_lead B of the leading error per unit step, c_lead the
    tensor of (1/2) curv (m, 6, 6) from :func:`kirchhoff_curvatures`.
    """
    return _spatial_stiffness(split, from_voigt(0.5 * curv))  # column kl's error per unit step


def _spatial_stiffness(split: ElementSplit, c: np.ndarray) -> sp.csr_matrix:
    """(3n, 3n) the assembled v grad N_a . c . grad N_b of per-cell spatial tangents c."""
    gN = split.D @ np.linalg.inv(split.F)
    v = np.linalg.det(split.F) * split.V0
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", v, gN, c, gN, optimize=True)
    m = split.cells.shape[0]
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


def _pairs() -> np.ndarray:
    """(6, 3, 3) E_kl = sym(e_k e_l) of the Voigt pairs in FEBio order."""
    return np.stack([_sym_unit(k, l) for k, l in FEBIO])  # noqa: E741


def _units() -> np.ndarray:
    """(6, 3, 3) e_k e_l (k <= l) of the Voigt pairs in FEBio order, unsymmetrised."""
    out = np.zeros((6, 3, 3))
    for col, (k, l) in enumerate(FEBIO):  # noqa: E741
        out[col, k, l] = 1.0
    return out


#: Scale of each column's step: the shear columns' perturbation doubled, or halved.
_SHEAR = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])[:, None, None]


def _times_F(E: np.ndarray):
    """F -> (m, 6, 3, 3) the spatial perturbations E_c F of the columns' E (6, 3, 3)."""
    return lambda F: np.einsum("ckl,mlj->mckj", E, F)


#: code -> (words: the perturbation as the engine made it, M_kl per unit step from F (m, 3, 3)
#: -> (m, 6, 3, 3), the differenced quantity: "tau" over J eps, "cauchy" sigma over eps,
#: "tau-no-J" tau over eps). "miehe" is the right scheme (Miehe 1996; Sun, Chaikof and
#: Levenston 2008): F + eps sym(e_k e_l) F, tau differenced, over J eps.
SCHEMES: Dict[str, Tuple[str, Any, str]] = {
    "miehe": (
        "F + eps sym(e_k e_l) F (Miehe's), the Kirchhoff stress tau differenced, over J eps",
        _times_F(_pairs()),
        "tau",
    ),
    "unsymmetrised": (
        "F + eps e_k e_l F, not symmetrised: the shear perturbation (k != l) carries a spin "
        "W = skew(e_k e_l), whose W tau - tau W enters the shear columns",
        _times_F(_units()),
        "tau",
    ),
    "shear-doubled": (
        "F + eps (e_k e_l + e_l e_k) F for the shear columns (an engineering shear strain "
        "2 eps divided by eps): the shear columns doubled",
        _times_F((1.0 + _SHEAR) * _pairs()),
        "tau",
    ),
    "shear-halved": (
        "F + eps/2 sym(e_k e_l) F for the shear columns (a tensor shear strain eps/2 divided by "
        "eps): the shear columns halved",
        _times_F((1.0 - 0.5 * _SHEAR) * _pairs()),
        "tau",
    ),
    "not-times-F": (
        "F + eps sym(e_k e_l), not multiplied by F on the right (a perturbation of F's "
        "components, not the spatial strain increment sym(e_k e_l) F)",
        lambda F: np.broadcast_to(_pairs(), (F.shape[0], 6, 3, 3)),
        "tau",
    ),
    "F-times": (
        "F + eps F sym(e_k e_l), F multiplied on the left (a material strain increment where "
        "the spatial one sym(e_k e_l) F belongs)",
        lambda F: np.einsum("mik,ckl->mcil", F, _pairs()),
        "tau",
    ),
    "cauchy": (
        "F + eps sym(e_k e_l) F with the Cauchy stress sigma differenced where the Kirchhoff "
        "stress tau = J sigma belongs",
        _times_F(_pairs()),
        "cauchy",
    ),
    "no-J": (
        "F + eps sym(e_k e_l) F with the difference of the Kirchhoff stress divided by eps "
        "where J eps belongs",
        _times_F(_pairs()),
        "tau-no-J",
    ),
}


def scheme_directions(code: str, F: np.ndarray) -> np.ndarray:
    """(m, 6, 3, 3) the perturbations M_kl per unit step of scheme ``code`` at F (m, 3, 3)."""
    return np.ascontiguousarray(SCHEMES[code][1](F))


def scheme_tangent(code: str, P: np.ndarray, A: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the spatial tangent c an engine gets in the limit of a small step from
    scheme ``code``: its columns Q'[M_kl] / divisor (tau'[M] = (A : M) F^T + P M^T), mirrored
    in (k, l), less the Jaumann terms. P: (m, 3, 3) the first Piola stress; A: (m, 3, 3, 3, 3)
    A[k, I, l, L] = dP_kI / dF_lL (:func:`conformance.diagnosis.elements.cell_piola`).
    """
    _, _, quantity = SCHEMES[code]
    M = scheme_directions(code, F)
    J = np.linalg.det(F)
    Ft = F.swapaxes(1, 2)
    dP = np.einsum("mkIlL,mclL->mckI", A, M)
    dtau = dP @ Ft[:, None] + P[:, None] @ M.swapaxes(2, 3)  # (m, 6, 3, 3)
    tau = P @ Ft
    sigma = tau / J[:, None, None]
    if quantity == "tau":
        cols = dtau / J[:, None, None, None]
    elif quantity == "tau-no-J":
        cols = dtau
    else:  # sigma' = tau' / J - sigma tr(F^-1 M)
        tr = np.einsum("mij,mcji->mc", np.linalg.inv(F), M)
        cols = dtau / J[:, None, None, None] - tr[:, :, None, None] * sigma[:, None]
    cols = 0.5 * (cols + cols.swapaxes(2, 3))  # tau of any F is symmetric: round-off only
    idx = np.empty((3, 3), dtype=int)
    for col, (k, l) in enumerate(FEBIO):  # noqa: E741
        idx[k, l] = idx[l, k] = col
    D = cols[:, idx].transpose(0, 3, 4, 1, 2)  # D[m, i, j, k, l] = cols[m, kl, i, j]
    return D - jaumann_terms(sigma)


#: A fitted step beyond this is no finite-difference step.
MAX_STEP = 1e-2


@dataclass(frozen=True)
class SchemeFit:
    """code: the scheme; step: the fitted eps (negative: backward); left: the stiffness error
    against the prediction with that step (relative, as the case's); moved: the prediction's
    own distance from the oracle (relative, at a zero step).
    """

    code: str
    step: float
    left: float
    moved: float


def fit_scheme(
    code: str,
    model: Any,
    split: ElementSplit,
    points: np.ndarray,
    D: sp.csr_matrix,
    scale: float,
    pa: Optional[Tuple[np.ndarray, np.ndarray]] = None,
) -> Optional[SchemeFit]:
    """Scheme ``code``'s prediction (limit plus a fitted step) against D = K - K_o (3n, 3n);
    scale: the stiffness denominator; None when the oracle cannot be evaluated on the path.
    """
    P, A = cell_piola(split) if pa is None else pa
    dc = scheme_tangent(code, P, A, split.F) - scheme_tangent("miehe", P, A, split.F)
    Kd = _spatial_stiffness(split, dc)
    M = scheme_directions(code, split.F)
    curv = kirchhoff_curvatures(model, split, points, M, SCHEMES[code][2])
    if curv is None or not np.all(np.isfinite(curv)):
        return None
    R = (D - Kd).tocsr()
    Bm = perturbation_basis(split, curv)
    bb = float(Bm.multiply(Bm).sum())
    step = float(Bm.multiply(R).sum()) / bb if bb > 0 else 0.0
    left = float(sparse_norm(R - step * Bm)) / scale
    return SchemeFit(code, step, left, float(sparse_norm(Kd)) / scale)


#: What a numerical scheme may leave beyond the tolerance, relative to the stiffness: the
#: round-off of differences at a step of sqrt(u) or more (why:
#: :data:`conformance.diagnosis.spatial_variants.NUMERICAL`).
ROUNDOFF = U**0.5


def scheme_findings(model: Any, split: ElementSplit, points: np.ndarray, D, scale, tol):
    """The findings of the wrong schemes of :data:`SCHEMES` whose prediction with a fitted
    step leaves at most max(tol, :data:`ROUNDOFF`) of the stiffness error, when the right
    scheme (Miehe's, with its own fitted step) does not; [] otherwise. D: K - K_o (3n, 3n);
    scale: the stiffness denominator; tol: the case's stiffness tolerance.
    """
    from conformance.diagnosis.findings import FULL, PARTIAL, Finding

    bound = max(tol, ROUNDOFF)
    pa = cell_piola(split)
    right = fit_scheme("miehe", model, split, points, D, scale, pa)
    if right is None or right.left <= bound:
        return []
    found = []
    for code, (words, _, _) in SCHEMES.items():
        if code == "miehe":
            continue
        fit = fit_scheme(code, model, split, points, D, scale, pa)
        if fit is None or fit.left > bound or fit.moved <= bound or abs(fit.step) > MAX_STEP:
            continue
        partial = fit.left > tol
        found.append(
            Finding(
                f"perturbation-scheme-{code}",
                "a numerical (finite-difference) spatial tangent (DDSDDE by perturbing F, as "
                f"Miehe's or Sun, Chaikof and Levenston's) whose perturbation is {words}; "
                f"{'forward' if fit.step > 0 else 'backward'} differences, step eps = "
                f"{abs(fit.step):.2e}",
                PARTIAL if partial else FULL,
                "each column predicted per cell as the derivative of the differenced stress "
                "along that perturbation, from the oracle's first elasticity tensor A = dP/dF "
                "(tau'[M] = (A : M) F^T + P M^T), the Jaumann terms removed as the driver does, "
                "plus the step's leading error (eps/2) Q''[M, M] (Q'' from the oracle's stress "
                f"along the perturbation), eps fitted: errors against your engine {fit.left:.1e}"
                + (
                    f", beyond the tolerance {tol:.0e} but below sqrt(u) = {ROUNDOFF:.1e}, the "
                    "round-off of differences at a step of sqrt(u) or more"
                    if partial
                    else ""
                )
                + f"; Miehe's right perturbation, its step fitted too, leaves {right.left:.1e}; "
                "the force matches",
                {"scheme": code, "step": fit.step, "residual": fit.left},
            )
        )
    return found
