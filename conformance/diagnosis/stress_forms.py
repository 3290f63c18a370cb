"""A stress error of one tensor form, the geometric stiffness following it, the tangent right.

A spatial engine builds its force from the Cauchy stress, f_a = -v sigma g_a, and its
stiffness from two parts, v (g_a . c . g_b) and the initial-stress part v (g_a . sigma g_b) I.
A term of sigma written wrongly (a material-frame tensor not pushed forward, S's I written
where F I F^T / J = b / J belongs; a coefficient kept twice, 2 mu (b^2 - b) / J for
mu (b^2 - b) / J) changes the force and the initial-stress part together, while the tangent c,
written apart from the stress, stays right. The error then has the form

    delta sigma = beta X   per cell, X one of :data:`FORMS` (I - b, b^2 - b, ...),

with beta a function of the invariants that is not known in advance: one unknown per cell (one
per group of cells in the same state, so that a homogeneous state has one), fitted by least
squares to the force error (-v beta X g_a) and the stiffness error (v beta (g_a . X g_b) I)
together, each weighted by its scale. Named when the fit leaves force and stiffness within the
case's tolerance; the per-cell beta is reported, and said as a parameter over J where beta J is
one parameter's value (or a simple multiple) in every cell.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "FORMS",
    "form_fit",
    "group_fit",
    "same_state_groups",
    "stress_form_findings",
    "stress_form_reading",
]

_EYE = np.eye(3)

#: form -> (the tensor per cell from b (m, 3, 3), what such an error is, in words).
FORMS: Dict[str, Tuple[Callable[[np.ndarray], np.ndarray], str]] = {
    "I - b": (
        lambda b: _EYE - b,
        "a term of S put into the Cauchy stress without its push-forward: X I / J written where "
        "F (X I) F^T / J = X b / J belongs (e.g. St Venant-Kirchhoff's lam tr E I)",
    ),
    "b^2 - b": (
        lambda b: b @ b - b,
        "a multiple of b^2 - b = 2 F E F^T (the push-forward of 2 E) in the Cauchy stress too "
        "many or too few (e.g. 2 mu (b^2 - b) / J for mu (b^2 - b) / J: the 2 of 2 mu E kept "
        "though F (2 E) F^T already holds it)",
    ),
    "b": (lambda b: b, "a multiple of b in the Cauchy stress too many or too few"),
}


#: Larger meshes are not read this way (a sparse column per cell).
MAX_CELLS = 20000


def _element_change(split: ElementSplit, X: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(fe (m, 4, 3), Ke (m, 12, 12)) of delta sigma = X (m, 3, 3) per cell: the force
    -v X g_a and the initial-stress stiffness v (g_a . X g_b) I, v = J V0, g = D F^-1.
    """
    m = split.cells.shape[0]
    g = split.D @ np.linalg.inv(split.F)
    v = np.linalg.det(split.F) * split.V0
    fe = -np.einsum("m,mij,maj->mai", v, X, g)
    geo = np.einsum("m,mai,mij,mbj->mab", v, g, X, g)
    return fe, np.einsum("mab,ik->maibk", geo, _EYE).reshape(m, 12, 12)


def group_fit(
    split: ElementSplit,
    fe: np.ndarray,
    Ke: np.ndarray,
    df: np.ndarray,
    dK: sp.spmatrix,
    s: Scales,
) -> Optional[np.ndarray]:
    """(m,) the coefficient per cell of the per-cell changes fe (m, 4, 3) and Ke (m, 12, 12)
    that best gives the force error df (n, 3) and stiffness error dK together (least squares,
    each weighted by its scale), one unknown per group of cells in the same state
    (:func:`same_state_groups`); None where the stiffness error has entries no cell reaches.
    """
    m, n3 = split.cells.shape[0], 3 * split.n
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    keys = (np.repeat(dof, 12, axis=1).astype(np.int64) * n3 + np.tile(dof, (1, 12))).ravel()
    pattern, where = np.unique(keys, return_inverse=True)
    dK = sp.coo_matrix(dK)
    dkeys = dK.row.astype(np.int64) * n3 + dK.col
    pos = np.minimum(np.searchsorted(pattern, dkeys), pattern.size - 1)
    inside = pattern[pos] == dkeys
    if np.linalg.norm(dK.data[~inside]) > 0.0:
        return None
    y = np.concatenate([np.asarray(df, dtype=np.float64).ravel() / s.force, np.zeros(pattern.size)])
    np.add.at(y, n3 + pos[inside], dK.data[inside] / s.stiffness)
    rows = np.concatenate([dof.ravel(), n3 + where.ravel()])
    group = same_state_groups(split.F @ split.F.swapaxes(1, 2))
    k = int(group.max()) + 1
    cols = np.concatenate([np.repeat(group, 12), np.repeat(group, 144)])
    data = np.concatenate([fe.reshape(-1) / s.force, Ke.reshape(-1) / s.stiffness])
    A = sp.csr_matrix((data, (rows, cols)), shape=(n3 + pattern.size, k))
    norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    norms[norms == 0] = 1.0
    sol = lsqr(A @ sp.diags(1.0 / norms), y, atol=1e-15, btol=1e-15, iter_lim=50 * k)
    return (sol[0] / norms)[group]


def form_fit(
    split: ElementSplit, form: str, df: np.ndarray, dK: sp.spmatrix, s: Scales
) -> Optional[np.ndarray]:
    """(m,) beta per cell of delta sigma = beta X (X: ``form`` of :data:`FORMS` at each cell's
    b) by :func:`group_fit` against the force error df (n, 3) and stiffness error dK.
    """
    b = split.F @ split.F.swapaxes(1, 2)
    fe, Ke = _element_change(split, FORMS[form][0](b))
    return group_fit(split, fe, Ke, df, dK, s)


def same_state_groups(b: np.ndarray) -> np.ndarray:
    """(m,) a group index per cell: cells whose b (m, 3, 3) agree to 1e-9 (relative) share one,
    so that a function of the state takes one value on them (a homogeneous state: one group;
    else, in general, a group per cell). One unknown per cell would leave a homogeneous state's
    fit free: there a constant stress error moves only the boundary nodes.
    """
    scale = max(float(np.abs(b).max()), 1e-300)
    key = np.round(b.reshape(len(b), 9) / (1e-9 * scale)).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    return group.ravel()


def _beta_words(beta: np.ndarray, J: np.ndarray, parameters: Dict[str, float]) -> str:
    """Beta per cell in words: as a parameter (or a simple multiple) over J when beta J is
    one in every cell, else its range.
    """
    bj = beta * J
    for name, value in parameters.items():
        for r in (1.0, -1.0, 2.0, -2.0, 0.5, -0.5):
            if value and np.all(np.abs(bj - r * value) <= 1e-6 * abs(value)):
                k = "" if r == 1.0 else ("-" if r == -1.0 else f"{r:g} ")
                return f"beta = {k}{name} / J in every cell"
    lo, hi = np.percentile(beta, [0, 100])
    return f"beta from {lo:.4g} to {hi:.4g} Pa over the cells"


def stress_form_findings(
    split: ElementSplit,
    f: np.ndarray,
    K: sp.spmatrix,
    s: Scales,
    tol: Tolerances,
    parameters: Optional[Dict[str, float]] = None,
) -> List[Finding]:
    """The forms of :data:`FORMS` whose fitted delta sigma = beta X, added to the oracle's force
    and stiffness (its tangent kept), matches the engine within ``tol``, the force wrong (several
    forms: ambiguous); [] otherwise.
    """
    if split.cells.shape[0] > MAX_CELLS:
        return []
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    e = errors(f, K, None, f0, K0, 0.0, s)
    if e.force <= tol.force:
        return []  # the force right: the stress is
    df = np.asarray(f, dtype=np.float64) - f0
    dK = sp.csr_matrix(K) - K0
    J = np.linalg.det(split.F)
    found = []
    for form, (tensor, words) in FORMS.items():
        beta = form_fit(split, form, df, dK, s)
        if beta is None:
            continue
        b = split.F @ split.F.swapaxes(1, 2)
        dfe, dKe = _element_change(split, beta[:, None, None] * tensor(b))
        pf, pK = assemble(split.cells, split.n, split.fe + dfe, split.Ke + dKe)
        left = errors(f, K, None, pf, pK, 0.0, s)
        if left.force > tol.force or left.stiffness > tol.stiffness:
            continue
        found.append(
            Finding(
                "stress-form",
                f"your Cauchy stress wrong by beta ({form}) per cell, in the force and the "
                f"initial-stress stiffness built from it, the material tangent right: {words}",
                FULL,
                f"delta sigma = beta ({form}) fitted with one unknown per cell ("
                + _beta_words(beta, J, parameters or {})
                + ") to the force and stiffness errors together: force error against your "
                f"engine {left.force:.1e}, stiffness {left.stiffness:.1e}",
                {"form": form, "beta_median": float(np.median(beta))},
            )
        )
    return ambiguous(found)


def stress_form_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force wrong, nothing named) with a stress error of one form named first
    (:func:`conformance.diagnosis.elements.split_reading`); unchanged otherwise.
    """
    from conformance.diagnosis.elements import split_reading
    from conformance.diagnosis.parameters import scalar_parameters

    values = scalar_parameters(ci.model)

    def finder(split, f, K, s_, tol):
        return stress_form_findings(split, f, K, s_, tol, values)

    return split_reading(diag, ci, out, ref, s, (finder,))
