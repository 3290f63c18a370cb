"""A spectral engine's principal block by differences of the principal Kirchhoff stresses.

A spectral (Bonet and Wood) engine builds the spatial tangent of an isotropic material in the
principal frame n_a of b from the principal Kirchhoff stresses tau_a(l_1, l_2, l_3), l_a = ln
lambda_a:

    J c = sum_ab (d tau_a / d l_b - 2 tau_a delta_ab) n_a n_a n_b n_b + (pair terms),

and an engine that does not derive d tau_a / d l_b by hand differences it, column by column,
with a step h: forward in l, (tau_a(l + h e_b) - tau_a(l)) / h, with a leading error (h/2)
d2 tau_a / d l_b2; central in l, with (h^2/6) d3 tau_a / d l_b3; or forward with a step
relative to the stretch, lambda_b (1 + h), that is l_b + ln(1 + h) divided by h. An SVD engine
(Teran's or Smith's eigensystem of dP/dF) differences dPsi/dsigma_a = tau_a / sigma_a in the
singular values instead, for the Hessian of its scaling modes: its error dH_ab is
sigma_a sigma_b dH_ab in d tau_a / d l_b, and its schemes are tried alike. The pair terms
(divided differences of the stresses themselves) are exact. Only the principal block is off, by
a matrix per cell that is one scheme's error per unit step (per unit h^2, central), measured by
simulating the scheme with a larger step (:data:`PROBE`) on the stresses at F = diag(lambda)
(an isotropic material's principal stresses do not depend on the frame) against the exact
derivative (central differences with a small step). Its stiffness, V0 grad N . (sum_ab dM_ab
n_a n_a n_b n_b) . grad N, is fitted to K - K_o with one unknown (h, or h^2), and named, partly
explaining (round-off and the higher orders are left), when it accounts for 99 % of the
stiffness error, as the other difference readings are. The engine may difference the whole
stress or only one part of it (the isochoric stresses, the volumetric pressure added
analytically): each part proportional to one parameter the energy is linear in is tried too.
On a homogeneous state with two equal stretches the tangent in their plane depends on the
basis each eigen-solver picks there: it is left free (six numbers per cell,
:func:`conformance.diagnosis.coincident_stretches.without_plane`) and the step fitted on the
rest. NumPy and MJED only; isotropic materials (no fibre frame).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.coincident_stretches import repeated_pair, without_plane
from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.parameters import scaled_models
from conformance.diagnosis.strain_differences import (
    EXPLAINED,
    StrainDifferenceFit,
    fit_step,
    fit_step_squared,
)

__all__ = [
    "PROBE",
    "Scheme",
    "SCHEMES",
    "principal_stresses",
    "stress_parts",
    "scheme_errors",
    "principal_stiffness",
    "principal_difference_fits",
    "principal_difference_reading",
    "scaling_rebuild_findings",
]

#: The step of the simulated schemes (their next order is 1e-3 of the leading one).
PROBE = 1e-3
#: The exact derivative's central step (its error 1e-9 of it, round-off 1e-12).
EXACT = 1e-4
#: A scheme's error per unit step below this share of the stresses is the simulation's own
#: round-off (u |tau| / PROBE^2, 2e-10), not a truncation error to fit.
SIGNIFICANT = 1e-6
#: A fitted step above this is no finite-difference step.
LARGEST_STEP = 0.1


@dataclass(frozen=True)
class Scheme:
    """One way of differencing the principal block: the quantity differenced ("tau": the
    principal Kirchhoff stresses tau_a, giving d tau_a / d l_b; "psi": dPsi/dsigma_a = tau_a /
    sigma_a, giving the Hessian d2Psi / dsigma_a dsigma_b of an SVD engine's scaling modes), the
    variable stepped ("log": l_b + h; "relative": sigma_b (1 + h); "absolute": sigma_b + h),
    central or forward (backward: a negative step), and the quotient in words.
    """

    quantity: str
    variable: str
    central: bool
    words: str


#: name -> scheme
SCHEMES = {
    "forward-log": Scheme(
        "tau", "log", False, "(tau_a(l + h e_b) - tau_a(l)) / h in the log-stretches l = ln lambda"
    ),
    "central-log": Scheme(
        "tau", "log", True, "(tau_a(l + h e_b) - tau_a(l - h e_b)) / (2 h) in the log-stretches"
    ),
    "forward-relative": Scheme(
        "tau",
        "relative",
        False,
        "(tau_a(lambda_b (1 + h)) - tau_a(lambda)) / h, a step relative to the stretch",
    ),
    "forward-relative-sigma": Scheme(
        "psi",
        "relative",
        False,
        "the Hessian d2Psi/dsigma_a dsigma_b as (Psi_a(sigma_b (1 + h)) - Psi_a(sigma)) / "
        "(h sigma_b), Psi_a = dPsi/dsigma_a, a step relative to the singular value",
    ),
    "forward-absolute-sigma": Scheme(
        "psi",
        "absolute",
        False,
        "the Hessian d2Psi/dsigma_a dsigma_b as (Psi_a(sigma + h e_b) - Psi_a(sigma)) / h, "
        "Psi_a = dPsi/dsigma_a",
    ),
    "central-absolute-sigma": Scheme(
        "psi",
        "absolute",
        True,
        "the Hessian d2Psi/dsigma_a dsigma_b as (Psi_a(sigma + h e_b) - Psi_a(sigma - h e_b)) "
        "/ (2 h), Psi_a = dPsi/dsigma_a",
    ),
}


def principal_stresses(
    model: Any, points: np.ndarray, split: ElementSplit, logs: np.ndarray
) -> Optional[np.ndarray]:
    """(m, 3) the principal Kirchhoff stresses tau_a of ``model`` at F = diag(exp(logs)) per
    cell (logs (m, 3)), from MJED; None where it cannot.
    """
    from conformance.diagnosis.routine_inputs import piola_at

    lam = np.exp(logs)
    F = np.zeros((logs.shape[0], 3, 3))
    F[:, [0, 1, 2], [0, 1, 2]] = lam
    at = piola_at(model, points, split, F, stiffness=False)
    if at is None or not np.all(np.isfinite(at[0])):
        return None
    return np.einsum("maa->ma", at[0]) * lam  # tau = P F^T, diagonal here


def stress_parts(model: Any) -> Dict[str, Any]:
    """{label: function(points, split, logs) -> (m, 3) or None}: the whole principal stress
    ("") and, for each scalar parameter the energy is linear in, the part proportional to it
    (its stress with the parameter doubled less the model's), kept where tripling it gives twice
    that part (linear).
    """

    def whole(points, split, logs):
        return principal_stresses(model, points, split, logs)

    parts: Dict[str, Any] = {"": whole}
    for name, (doubled, tripled) in scaled_models(model, (2.0, 3.0)):

        def part(points, split, logs, doubled=doubled, tripled=tripled):
            base = principal_stresses(model, points, split, logs)
            two = principal_stresses(doubled, points, split, logs)
            three = principal_stresses(tripled, points, split, logs)
            if base is None or two is None or three is None:
                return None
            p = two - base
            scale = max(np.abs(base).max(), 1e-300)
            return p if np.abs(three - base - 2.0 * p).max() <= 1e-9 * scale else None

        parts[name] = part
    return parts


def _frame(split: ElementSplit) -> Tuple[np.ndarray, np.ndarray]:
    """(logs (m, 3), n (m, 3, 3)): the log principal stretches and the principal directions of
    b = F F^T (columns), in the same order.
    """
    x, n = np.linalg.eigh(split.F @ split.F.swapaxes(1, 2))
    return 0.5 * np.log(x), n


def _shift(logs: np.ndarray, variable: str, t: float, b: int) -> np.ndarray:
    """(m, 3) the change of the log-stretches when stretch b is stepped by t in ``variable``."""
    out = np.zeros_like(logs)
    if variable == "log":
        out[:, b] = t
    elif variable == "relative":
        out[:, b] = np.log1p(t)
    else:  # absolute: sigma_b + t
        out[:, b] = np.log1p(t / np.exp(logs[:, b]))
    return out


def scheme_errors(stress, points: np.ndarray, split: ElementSplit, logs: np.ndarray, base=None):
    """{scheme: (m, 3, 3) the error of d tau_a / d l_b per unit step (per unit h^2, central)}
    of :data:`SCHEMES` for the principal stresses ``stress`` (a function of
    :func:`stress_parts`); None where they cannot be evaluated. A scheme on Psi_a = tau_a /
    sigma_a errs in d2Psi / dsigma_a dsigma_b by dH, in d tau_a / d l_b by sigma_a sigma_b dH.
    """
    sigma = np.exp(logs)
    cache: Dict[bytes, Optional[np.ndarray]] = {}
    if base is not None:  # the stresses at logs, evaluated by the caller
        cache[np.zeros_like(logs).tobytes()] = base

    def at(shift: np.ndarray, quantity: str) -> Optional[np.ndarray]:
        key = shift.tobytes()
        if key not in cache:
            cache[key] = stress(points, split, logs + shift)
        tau = cache[key]
        if tau is None or quantity == "tau":
            return tau
        return tau / np.exp(logs + shift)

    base = at(np.zeros_like(logs), "tau")
    if base is None:
        return None
    exact = np.empty(logs.shape + (3,))  # d tau_a / d l_b
    for b in range(3):
        plus = at(_shift(logs, "log", EXACT, b), "tau")
        minus = at(_shift(logs, "log", -EXACT, b), "tau")
        if plus is None or minus is None:
            return None
        exact[:, :, b] = (plus - minus) / (2 * EXACT)
    # d2Psi / dsigma_a dsigma_b = (d tau_a / d l_b - delta_ab tau_a) / (sigma_a sigma_b)
    pair = sigma[:, :, None] * sigma[:, None, :]
    hessian = (exact - np.einsum("ma,ab->mab", base, np.eye(3))) / pair
    out = {}
    for name, sc in SCHEMES.items():
        moved = np.empty_like(exact)
        zero = at(np.zeros_like(logs), sc.quantity)
        for b in range(3):
            fwd = at(_shift(logs, sc.variable, PROBE, b), sc.quantity)
            back = at(_shift(logs, sc.variable, -PROBE, b), sc.quantity) if sc.central else None
            if fwd is None or (sc.central and back is None):
                return None
            quotient = (fwd - back) / (2 * PROBE) if sc.central else (fwd - zero) / PROBE
            if sc.quantity == "psi" and sc.variable == "relative":
                quotient = quotient / sigma[:, b : b + 1]
            moved[:, :, b] = quotient
        error = moved - (exact if sc.quantity == "tau" else hessian)
        if sc.quantity == "psi":
            error = error * pair
        out[name] = error / (PROBE**2 if sc.central else PROBE)
    return out


def principal_stiffness(split: ElementSplit, n: np.ndarray, dM: np.ndarray) -> sp.csr_matrix:
    """(3n, 3n) the stiffness of a principal-block change dM (m, 3, 3) of J c, sum_ab dM_ab
    n_a n_a n_b n_b, integrated as V0 grad N . (J c) . grad N (grad N = F^-T D_a).
    """
    nn = np.einsum("mia,mja->maij", n, n)  # n_a (x) n_a
    Jc = np.einsum("mab,maij,mbkl->mijkl", dM, nn, nn, optimize=True)
    gN = split.D @ np.linalg.inv(split.F)
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", split.V0, gN, Jc, gN, optimize=True)
    m = split.F.shape[0]
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


def principal_difference_fits(
    model: Any, split: ElementSplit, points: np.ndarray, D: sp.csr_matrix, K_o: sp.csr_matrix
) -> List[Tuple[str, str, StrainDifferenceFit]]:
    """[(part, scheme, fit)]: every part of :func:`stress_parts` and scheme of :data:`SCHEMES`
    whose error accounts for :data:`EXPLAINED` of D = K - K_o, best first; [] for a model
    with a fibre frame (not isotropic) or where MJED cannot evaluate it.
    """
    if getattr(model, "frame", None) is not None:
        return []
    logs, n = _frame(split)
    pair = repeated_pair(split)
    if pair is not None:
        # Two equal stretches on a homogeneous state: in their plane each eigen-solver picks
        # its own basis, and the principal block's share there depends on it; the in-plane
        # tangent is left free and the step fitted on what is outside it.
        project = without_plane(split, pair)
        D = project(D)
    found = []
    for label, stress in stress_parts(model).items():
        tau = stress(points, split, logs)
        errs = None if tau is None else scheme_errors(stress, points, split, logs, tau)
        if errs is None:
            continue
        size = float(np.linalg.norm(tau))
        for scheme, dM in errs.items():
            if not np.all(np.isfinite(dM)):
                continue
            if float(np.linalg.norm(dM)) <= SIGNIFICANT * size:
                # a part linear in the log-stretches (k0 ln J) differences exactly: what is
                # left is the simulation's round-off, which must not be fitted as a scheme
                continue
            for read, block in _READ_AS.items():
                basis = principal_stiffness(split, n, block(dM))
                if pair is not None:
                    basis = project(basis)
                squared = SCHEMES[scheme].central
                fit = (
                    fit_step_squared(basis, D, K_o, "principal")
                    if squared
                    else fit_step(basis, D, K_o, "principal")
                )
                if fit is not None and fit.explained >= EXPLAINED and fit.step <= LARGEST_STEP:
                    found.append((label, scheme + read, fit))
    return sorted(found, key=lambda t: -t[2].explained)


#: How the engine uses its differenced (non-symmetric) 3 x 3 block -> the block it uses: as it
#: is, symmetrised, or one triangle mirrored (numpy.linalg.eigh reads only its lower triangle,
#: and an eigensystem engine hands it the block unsymmetrised; which entries that keeps depends
#: on the engine's order of the stretches: here they ascend, as eigh gives them, and the
#: "larger" triangle keeps the rows of the larger stretch, d Q_a / d l_b with lambda_a >
#: lambda_b, the lower triangle of an engine whose stretches ascend, the upper of one whose
#: singular values descend, as numpy.linalg.svd gives them).
_READ_AS = {
    "": lambda M: M,
    "+symmetrised": lambda M: 0.5 * (M + np.swapaxes(M, 1, 2)),
    "+larger": lambda M: np.tril(M) + np.swapaxes(np.tril(M, -1), 1, 2),
    "+smaller": lambda M: np.triu(M) + np.swapaxes(np.triu(M, 1), 1, 2),
}

#: words for a scheme's use of its block (after the "+" in a fitted scheme's name)
_READ_WORDS = {
    "symmetrised": " (the differenced block symmetrised before use)",
    "larger": " (one triangle of the differenced block mirrored, as an eigen-solver of "
    "symmetric matrices reads it: the entries d/dl_b of the larger stretch's row, the lower "
    "triangle with the stretches in ascending order)",
    "smaller": " (one triangle of the differenced block mirrored, as an eigen-solver of "
    "symmetric matrices reads it: the entries d/dl_b of the smaller stretch's row, the lower "
    "triangle with the stretches in descending order, as an SVD gives them)",
}


def _part_words(label: str) -> str:
    return (
        "the principal Kirchhoff stresses"
        if not label
        else f"the part of the principal Kirchhoff stresses proportional to {label} (the rest "
        "derived exactly)"
    )


def principal_difference_reading(diag, ci, out, ref, s):
    """``diag`` (the force right, nothing named) with the principal block by differences named
    first, partly explaining, when a scheme fits (:func:`principal_difference_fits`; several
    alike within 0.1 %: the best, the others said); unchanged otherwise.
    """
    from conformance.diagnosis.elements import case_split
    from conformance.diagnosis.findings import PARTIAL, Finding, named_first

    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    K_o = sp.csr_matrix(ref.stiffness)
    D = (sp.csr_matrix(out.stiffness) - K_o).tocsr()
    with np.errstate(all="ignore"):
        fits = principal_difference_fits(ci.model, split, ci.points, D, K_o)
        if not fits:
            rebuilt = scaling_rebuild_findings(
                ci.model, split, ci.points, out.stiffness, K_o, s, diag.tolerances
            )
            return named_first(diag, rebuilt) if rebuilt else diag
    label, named, fit = fits[0]
    scheme, _, read = named.partition("+")
    alike = [
        f"{_part_words(lb)}, {sc.replace('-', ' ')}"
        for lb, sc, f in fits[1:]
        if f.explained >= fit.explained - 1e-3
    ]
    quotient, squared = SCHEMES[scheme].words + _READ_WORDS.get(read, ""), SCHEMES[scheme].central
    direction = "" if squared or fit.scheme == "forward" else " (backward: a negative step)"
    return named_first(
        diag,
        [
            Finding(
                "principal-finite-difference",
                (
                    "a spectral engine's principal block d tau_a / d ln lambda_b by finite "
                    f"differences of {_part_words(label)}: "
                    if SCHEMES[scheme].quantity == "tau"
                    else "an SVD engine's scaling modes by finite differences of dPsi/dsigma_a "
                    f"(from {_part_words(label)}): "
                )
                + f"{quotient}, step h = {fit.step:.2e}{direction}",
                PARTIAL,
                "K - K_oracle is that scheme's error in the principal block of J c per unit "
                + ("h^2" if squared else "h")
                + f" (measured by simulating it with h = {PROBE:g} on the oracle's principal "
                "stresses against their exact derivative; the pair terms exact), fitted with one "
                f"unknown: it accounts for {100 * fit.explained:.2f} % of the stiffness error "
                f"(left: {fit.residual:.1e}, the higher orders and round-off); the force matches"
                + (f" (as well: {'; '.join(alike)})" if alike else ""),
                {
                    "step": fit.step,
                    "scheme": named,
                    "part": label,
                    "explained": fit.explained,
                },
            )
        ],
    )


def _exact_blocks(split: ElementSplit, n: np.ndarray):
    """(tau (m, 3), d tau_a / d l_b (m, 3, 3)) in the principal frame n (m, 3, 3; columns) of
    b, exact to round-off: from the oracle's per-cell spatial tangent (its element split),
    J c_aabb = d tau_a / d l_b - 2 tau_a delta_ab.
    """
    from conformance.diagnosis.elements import cell_piola
    from conformance.diagnosis.invariant_pieces import cell_tensors
    from conformance.diagnosis.spatial_tangent import spatial_cells

    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    sc = spatial_cells(split, t.S, t.CC)
    J = np.linalg.det(split.F)
    tau = J[:, None] * np.einsum("mia,mij,mja->ma", n, sc.sigma, n)
    Jc = J[:, None, None] * np.einsum("mia,mja,mijkl,mkb,mlb->mab", n, n, sc.c, n, n, optimize=True)
    return tau, Jc + 2.0 * np.einsum("ma,ab->mab", tau, np.eye(3))


def _rows_for_columns(H: np.ndarray, descending: bool, signs=(1.0, 1.0, 1.0)) -> np.ndarray:
    """H (m, 3, 3) rebuilt from its eigen-decomposition with the eigenvector matrix's rows taken
    for its columns (W^T Lambda W for W Lambda W^T), the stretches ordered ascending (as they
    are here) or descending (as an SVD gives them). The result depends on the sign of each
    eigenvector, which the eigen-solver picks: ``signs`` multiplies them (W diag(signs)).
    """
    order = slice(None, None, -1) if descending else slice(None)
    Ho = H[:, order, order]
    w, W = np.linalg.eigh(0.5 * (Ho + np.swapaxes(Ho, 1, 2)))
    W = W * np.asarray(signs)
    rebuilt = np.einsum("mki,mk,mkj->mij", W, w, W)  # W^T diag(w) W
    return rebuilt[:, order, order]


#: Eigenvector signs that change W^T Lambda W (a global sign does not).
_SIGNS = ((1.0, 1.0, 1.0), (1.0, 1.0, -1.0), (1.0, -1.0, 1.0), (-1.0, 1.0, 1.0))


def scaling_rebuild_findings(model: Any, split: ElementSplit, points, K, K_o, s, tol):
    """An SVD engine's scaling block d2Psi/dsigma_a dsigma_b rebuilt from its eigen-pairs with
    the eigenvector matrix's rows taken for its columns (the singular values in either order),
    predicted exactly from the oracle's principal stresses; [] where none matches, for a model
    with a fibre frame, or where the rebuilt block is the right one (a diagonal Hessian).
    """
    from conformance.diagnosis.findings import FULL, Finding

    if getattr(model, "frame", None) is not None:
        return []
    logs, n = _frame(split)
    tau, exact = _exact_blocks(split, n)
    sigma = np.exp(logs)
    pair = sigma[:, :, None] * sigma[:, None, :]
    H = (exact - np.einsum("ma,ab->mab", tau, np.eye(3))) / pair
    D = (sp.csr_matrix(K) - sp.csr_matrix(K_o)).tocsr()
    plane = repeated_pair(split)
    # two equal stretches: the tangent in their plane depends on each solver's basis there,
    # left free (without_plane) and the rest compared
    project = without_plane(split, plane) if plane is not None else (lambda X: X)
    D = project(D)
    found = []
    for descending, signs in itertools.product((True, False), _SIGNS):
        dM = (_rows_for_columns(H, descending, signs) - H) * pair
        change = project(principal_stiffness(split, n, dM))
        if _matches(change, D, s, tol):
            order = "descending (as an SVD gives them)" if descending else "ascending"
            found.append(
                Finding(
                    "scaling-eigenvectors-as-rows",
                    "an SVD engine's scaling modes built from the rows of the eigenvector matrix "
                    "of the Hessian d2Psi/dsigma_a dsigma_b where its columns are the "
                    f"eigenvectors (W^T Lambda W for W Lambda W^T, singular values {order})",
                    FULL,
                    "the oracle's principal Hessian per cell (from its principal stresses by "
                    "central differences) eigen-decomposed and rebuilt so, its change pushed "
                    "along n_a n_a n_b n_b and assembled, matches your stiffness within the "
                    "tolerance; the force matches",
                    {"descending": descending},
                )
            )
            break
    return found


def _matches(change: sp.spmatrix, D: sp.spmatrix, s, tol) -> bool:
    """Whether the stiffness error D is ``change`` within ``tol`` (relative to the case's
    stiffness scale) and ``change`` is not itself within it (a rebuild that changes nothing).
    """
    from scipy.sparse.linalg import norm as sparse_norm

    limit = tol.stiffness * s.stiffness
    return sparse_norm(change) > limit and sparse_norm(D - change) <= limit
