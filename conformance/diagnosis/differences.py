"""A tangent from differences of each element's force, with a step chosen per cell.

:func:`conformance.diagnosis.tangent.fit_finite_difference` fits differences of the assembled
force, one step per dof. Engines more often difference each element's own force, with a step
of their own per cell (a fraction of the cell's longest edge, say): the error of cell c is then
(h_c / 2) G1_c (forward) or (h_c^2 / 6) G2_c (central), G1_c and G2_c the first and second
derivatives of each column of the cell's element matrix along its own local dof, and no single
step per dof reproduces the sum. Here G1_c and G2_c are taken from the oracle's element matrices
(:mod:`conformance.diagnosis.elements`: MJED's, checked against the oracle) on the mesh with its
cells pulled apart, so that one local dof of every cell moves at once (24 evaluations), and each
step rule (absolute; a fraction of the longest, shortest or mean edge, or of the cube root of
the volume; relative to the coordinate) is fitted with one unknown.

A step so small that round-off dominates leaves no such structure: the force is exact and the
stiffness error is noise of size about u |f_e| / h (u the double unit round-off), which breaks
the symmetry of K and the zero sum of each column over the nodes (the truncation error of
differences and any error from a formula keep it: a column is the change of a force whose
nodal sum is zero), and is not float32's (the values are not float32 numbers, and the error of
an entry does not scale with the entry). :func:`roundoff_dominated` names it only on that
evidence, and only when no truncation fit accounts for the error.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.sparsity import OFF_PATTERN, off_pattern_fraction
from conformance.diagnosis.tangent import step_fits

__all__ = [
    "CellDerivatives",
    "cell_column_derivatives",
    "ElementDifferenceFit",
    "fit_element_differences",
    "RoundoffDifferences",
    "roundoff_dominated",
    "exact_node_blocks",
    "element_difference_reading",
]

#: Fraction of the stiffness error a fit must account for to be named.
EXPLAINED = 0.99

#: Fraction of K's node blocks left exact above which an error is not round-off noise.
EXACT_BLOCKS = 0.2

_U64 = 2.0**-53


@dataclass(frozen=True)
class CellDerivatives:
    """G1, G2: (m, 12, 12), column j of cell c differentiated once and twice along local dof j;
    x: (m, 12) the local dofs' current coordinates; edges: (m, 6) rest edge lengths;
    V0: (m,) rest volumes.
    """

    G1: np.ndarray
    G2: np.ndarray
    x: np.ndarray
    edges: np.ndarray
    V0: np.ndarray


def cell_column_derivatives(
    model: Any, points: np.ndarray, cells: np.ndarray, positions: np.ndarray
) -> Optional[CellDerivatives]:
    """The per-cell column derivatives of MJED's element matrices (None when MJED cannot
    evaluate the model or a perturbed state).
    """
    import mjed

    m = cells.shape[0]
    X = points[cells]
    e = X[:, :, None, :] - X[:, None, :, :]
    iu = np.triu_indices(4, 1)
    edges = np.sqrt((e**2).sum(-1))[:, iu[0], iu[1]]
    delta = 1e-3 * edges.mean(axis=1)
    loose = np.arange(4 * m).reshape(m, 4)
    xs = positions[cells].reshape(-1, 3)
    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), loose), model)
        K0 = field.element_stiffness(xs)
        G1 = np.empty_like(K0)
        G2 = np.empty_like(K0)
        for j in range(12):
            b, comp = divmod(j, 3)
            xp, xm = xs.copy(), xs.copy()
            xp[loose[:, b], comp] += delta
            xm[loose[:, b], comp] -= delta
            Kp = field.element_stiffness(xp)[:, :, j]
            Km = field.element_stiffness(xm)[:, :, j]
            G1[:, :, j] = (Kp - Km) / (2.0 * delta[:, None])
            G2[:, :, j] = (Kp - 2.0 * K0[:, :, j] + Km) / delta[:, None] ** 2
    except Exception:  # noqa: BLE001 - not an MJED material, or an inverted perturbed cell
        return None
    V0 = np.abs(np.linalg.det(np.swapaxes(X[:, 1:] - X[:, :1], 1, 2))) / 6.0
    return CellDerivatives(G1, G2, positions[cells].reshape(m, 12), edges, V0)


#: Step rules of an element-wise difference: name -> (words with the fitted factor, weight of
#: cell c's column j (m, 12) from the derivatives).
_RULES: Dict[str, Tuple[str, Callable[[CellDerivatives], np.ndarray]]] = {
    "absolute": ("h = {:.2e} m", lambda d: np.ones_like(d.x)),
    "longest edge": (
        "h_c = {:.2e} x the cell's longest edge",
        lambda d: np.repeat(d.edges.max(axis=1)[:, None], 12, axis=1),
    ),
    "shortest edge": (
        "h_c = {:.2e} x the cell's shortest edge",
        lambda d: np.repeat(d.edges.min(axis=1)[:, None], 12, axis=1),
    ),
    "mean edge": (
        "h_c = {:.2e} x the cell's mean edge",
        lambda d: np.repeat(d.edges.mean(axis=1)[:, None], 12, axis=1),
    ),
    "cube root of the volume": (
        "h_c = {:.2e} x V_c^(1/3)",
        lambda d: np.repeat(np.cbrt(d.V0)[:, None], 12, axis=1),
    ),
    "relative": ("h_j = {:.2e} |x_j|", lambda d: np.abs(d.x)),
}


@dataclass(frozen=True)
class ElementDifferenceFit:
    """scheme ("forward", "backward", "central"); rule (a key of the step rules); step (h [m]
    or the dimensionless factor); symmetrised; explained: fraction of ||K - K_o|| accounted for;
    residual: what is left, relative to ||K_o||; same: other rules that predict the same.
    """

    scheme: str
    rule: str
    step: float
    symmetrised: bool
    explained: float
    residual: float
    same: Tuple[str, ...] = ()

    def words(self) -> str:
        h = _RULES[self.rule][0].format(self.step)
        sym = ", then symmetrised" if self.symmetrised else ""
        also = f" (equivalently, on this mesh: {', '.join(self.same)})" if self.same else ""
        if self.scheme == "complex step":
            return (
                f"a complex step of each element's force, Im f(x + i h e_j) / h, with {h}{sym}"
                f"{also}: the step too large (what is left is its truncation error)"
            )
        return f"{self.scheme} differences of each element's force with {h}{sym}{also}"


def fit_element_differences(
    split: ElementSplit, d: CellDerivatives, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> Optional[ElementDifferenceFit]:
    """The scheme, per-cell step rule and factor that best explain D = K - K_o, or None."""
    nD = float(sparse_norm(D))
    if nD == 0.0:
        return None
    nK = float(sparse_norm(K_o))
    zeros = np.zeros((split.cells.shape[0], 4, 3))
    fits: List[Tuple[ElementDifferenceFit, sp.csr_matrix]] = []
    for G, order in ((d.G1, 1), (d.G2, 2)):
        for rule, (_, weight) in _RULES.items():
            w = weight(d) ** order / (2.0 if order == 1 else 6.0)
            B = assemble(split.cells, split.n, zeros, G * w[:, None, :])[1]
            for symmetrised, scheme, step, left, pred in step_fits(B, D, order):
                fit = ElementDifferenceFit(
                    scheme, rule, step, symmetrised, 1 - left / nD, left / nK
                )
                fits.append((fit, pred))
    if not fits:
        return None
    best, pred = max(fits, key=lambda t: t[0].explained)
    same = tuple(
        _RULES[f.rule][0].format(f.step)
        for f, p in fits
        if f is not best
        and f.scheme == best.scheme
        and f.symmetrised == best.symmetrised
        and float(sparse_norm(p - pred)) <= 1e-6 * nD
    )
    return ElementDifferenceFit(
        best.scheme,
        best.rule,
        best.step,
        best.symmetrised,
        best.explained,
        best.residual,
        same,
    )


# ------------------------------------------------------------------ round-off dominated
@dataclass(frozen=True)
class RoundoffDifferences:
    """The evidence of a round-off-dominated difference tangent.

    asymmetry: ||K - K^T|| / (2 ||K - K_o||) (about 0.7 for noise, 0 for a symmetric mistake);
    balance: the error's column sums over the nodes (sum_a D[3a + i, j], per component i)
    against ||K - K_o||: about 1 for noise; about 0 for an error built from per-cell matrices
    D^T A D and for the truncation error of differences (each column of K is the change of a
    force whose nodal sum is zero for every x);
    representable: fraction of K's values that are float32 numbers; outside32: fraction of the
    error (in norm) on entries whose error exceeds float32's relative rounding of the entry;
    step: the step the noise level implies, u ||f_e|| / ||K_e - K_o,e|| per cell, median [m];
    off_pattern: fraction of the error on node pairs that share no cell (0 for differences);
    exact_blocks: fraction of K's nonzero 3x3 node blocks whose error is zero to double
    round-off of the block: about 0 for noise (every difference carries round-off), a half or
    more for a storage mistake (blocks of one triangle, say, transposed: the others exact);
    smallest_step: the spacing of doubles at the median node coordinate [m] (nan: positions
    unknown). A step below it does not move most nodes at all (x + h == x), so noise that
    implies such a step is not the round-off of differences: values at the wrong entries, say.
    """

    asymmetry: float
    balance: float
    representable: float
    outside32: float
    step: float
    exact_blocks: float = 0.0
    off_pattern: float = 0.0
    smallest_step: float = float("nan")

    @property
    def possible_step(self) -> bool:
        """False when the implied step is below the spacing of doubles at the coordinates."""
        return not self.step < self.smallest_step

    @property
    def holds(self) -> bool:
        return (
            self.possible_step
            and self.asymmetry > 0.4
            and self.balance > 0.01
            and self.representable < 0.5
            and self.outside32 > 0.5
            # Round-off reaches every block; an error confined to some blocks is structured.
            and self.exact_blocks < EXACT_BLOCKS
            # Differences change only the forces around the perturbed node: never off the
            # mesh's pattern (conformance.diagnosis.sparsity).
            and not self.off_pattern > OFF_PATTERN
        )


def roundoff_dominated(
    split: ElementSplit, K: sp.spmatrix, K_o: sp.spmatrix
) -> Optional[RoundoffDifferences]:
    """The noise signature of a difference tangent whose step is too small (None: D is zero, or
    the mesh has more than 1000 nodes, where the per-cell blocks of D are not gathered).
    """
    K = sp.csr_matrix(K)
    D = (K - sp.csr_matrix(K_o)).tocsr()
    nD = float(sparse_norm(D))
    if nD == 0.0:
        return None
    asym = float(sparse_norm(K - K.T)) / (2.0 * nD)
    balance = float(np.linalg.norm(_sums_by_component(D.T.tocsr())) / nD)
    vals = K.data[K.data != 0]
    rep = float(np.mean(vals.astype(np.float32).astype(np.float64) == vals)) if vals.size else 0.0
    Ko = sp.csr_matrix(K_o)
    Dc = sp.coo_matrix(D)
    ko = np.asarray(Ko[Dc.row, Dc.col]).ravel()
    big = np.abs(Dc.data) > 2.0**-23 * np.abs(ko)
    outside = float(np.linalg.norm(Dc.data[big]) / nD)
    # Per cell, a forward difference of the element force with step h has round-off of about
    # u |f_e| / h in each column: the step that makes that the observed error.
    m = split.cells.shape[0]
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    Dd = D.toarray() if D.shape[0] <= 3000 else None
    if Dd is None:
        return None
    block = Dd[dof[:, :, None], dof[:, None, :]]  # (m, 12, 12), shared entries counted by each
    err = np.linalg.norm(block.reshape(m, -1), axis=1)
    fe = np.linalg.norm(split.fe.reshape(m, -1), axis=1)
    ok = err > 0
    step = float(np.median(_U64 * fe[ok] * np.sqrt(12.0) / err[ok])) if np.any(ok) else np.nan
    smallest = (
        float(np.spacing(np.median(np.abs(split.positions))))
        if split.positions is not None
        else np.nan
    )
    return RoundoffDifferences(
        asym,
        balance,
        rep,
        outside,
        step,
        exact_node_blocks(D, Ko),
        off_pattern_fraction(split.cells, D),
        smallest,
    )


def exact_node_blocks(D: sp.csr_matrix, K_o: sp.csr_matrix) -> float:
    """Fraction of K_o's nonzero 3x3 node blocks (3n, 3n) whose error D is below 1e3 double
    unit round-offs of the block's norm.
    """
    n = K_o.shape[0] // 3

    def block_norms(A: sp.csr_matrix) -> sp.csr_matrix:
        C = sp.coo_matrix(A)
        return sp.csr_matrix((C.data**2, (C.row // 3, C.col // 3)), shape=(n, n))

    Bo = block_norms(K_o)
    Bd = block_norms(D)
    Bo.sum_duplicates()
    C = sp.coo_matrix(Bo)
    keep = C.data > 0
    if not np.any(keep):
        return 0.0
    d = np.asarray(Bd[C.row[keep], C.col[keep]]).ravel()
    return float(np.mean(np.sqrt(d) <= 1e3 * _U64 * np.sqrt(C.data[keep])))


def _sums_by_component(D: sp.spmatrix) -> np.ndarray:
    """(rows, 3): sum over nodes b of D[r, 3b + j] for each row r and column component j."""
    C = sp.coo_matrix(D)
    out = np.zeros((D.shape[0], 3))
    np.add.at(out, (C.row, C.col % 3), C.data)
    return out


def element_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force right, nothing explaining the stiffness) with an element-wise
    difference tangent named when the fit accounts for 99 % of the stiffness error, or a
    round-off-dominated one when the error has that signature; unchanged otherwise.
    """
    import dataclasses

    from conformance.diagnosis.elements import element_split
    from conformance.diagnosis.findings import PARTIAL, Finding

    tol = diag.tolerances
    if diag.errors.force > tol.force or tol.precision != "double":
        return diag
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    K = sp.csr_matrix(out.stiffness)
    K_o = sp.csr_matrix(ref.stiffness)
    D = (K - K_o).tocsr()
    d = cell_column_derivatives(ci.model, ci.points, ci.cells, ci.positions)
    fit = None if d is None else fit_element_differences(split, d, D, K_o)
    finding = None
    if fit is not None and fit.explained >= EXPLAINED:
        finding = Finding(
            "finite-difference",
            f"a finite-difference tangent: {fit.words()}",
            PARTIAL,
            "K - K_oracle is the leading error of that scheme cell by cell (the derivative of "
            "each column of the element matrix along its own dof, times the cell's step, from "
            "the oracle's element matrices), fitted with one unknown: it accounts for "
            f"{100 * fit.explained:.3f} % of the stiffness error (left: {fit.residual:.1e}); "
            "the force matches",
            {**dataclasses.asdict(fit), "same": list(fit.same)},
        )
    else:
        r = roundoff_dominated(split, K, K_o)
        structured = fit is not None and fit.explained > 0.5
        if r is not None and r.holds and not structured:
            finding = Finding(
                "finite-difference-roundoff",
                "a finite-difference tangent with a step too small: the round-off of the "
                "differences dominates its error",
                PARTIAL,
                f"the force matches; the stiffness error is noise: it breaks K's symmetry "
                f"(antisymmetric part {r.asymmetry:.2f} of the error) and the balance of K's "
                f"rows and columns over the nodes ({r.balance:.2f} of the error, where any "
                "error built from element matrices sums to zero), it is not float32's "
                f"({100 * r.representable:.0f} % of the values are float32 numbers; "
                f"{100 * r.outside32:.0f} % of the error on entries beyond float32's relative "
                "rounding), and no truncation error of a difference scheme accounts for it "
                + (f"(best: {100 * fit.explained:.0f} %)" if fit is not None else "")
                + f"; the noise is u |f_e| / h for a step of order {r.step:.0e} m or somewhat "
                "larger (u the double unit round-off, f_e the element force): use a step near "
                "sqrt(u) times the cell size, or the analytic tangent",
                {
                    "asymmetry": r.asymmetry,
                    "balance": r.balance,
                    "representable": r.representable,
                    "outside32": r.outside32,
                    "step_order": r.step,
                    "exact_blocks": r.exact_blocks,
                },
            )
    if finding is None:
        return diag
    return dataclasses.replace(
        diag, findings=[finding, *(f for f in diag.findings if f.code != "unexplained")]
    )
