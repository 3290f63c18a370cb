"""A tangent of a sum of eigenvalue powers taken coaxial: the eigenvectors held fixed.

For P = tr C^q = sum_i lambda_i^q (Ogden's principal-stretch sums, q = alpha/2), dP/dC =
f(C) with f(lambda) = q lambda^(q-1), and its derivative in the principal frame N_i holds
f'(lambda_i) on the pairs i = i and the divided differences
theta_ij = (f(lambda_i) - f(lambda_j)) / (lambda_i - lambda_j) on the pairs i != j (the
rotation of the principal directions). An engine that differentiates f(C) with its
eigenvectors held fixed keeps the first and drops the second: per cell, its tangent lacks
4 dW/dP X, X_pqrs = sum_(i != j) theta_ij (N_pi N_qj N_ri N_sj + N_pi N_qj N_rj N_si) / 2, with
dW/dP unknown. Where two eigenvalues are equal (a uniaxial stretch) the engine's eigenvectors
in their plane are whatever its round-off makes them: there dW/dP is read from the oracle's
stress (S = 2 dW/dP q C^(q-1) + dW/dJ J C^-1), the X part taken with that known coefficient,
and the turn of the kept terms f' (n1^4 + n2^4) in the plane fitted with two unknowns. The
fit: one unknown per cell against the stiffness error
(:func:`conformance.diagnosis.second_derivative.fit_cell_term`); named when it leaves the
stiffness within the tolerance, the force being right.
"""

from __future__ import annotations

from typing import Any, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.second_derivative import fit_cell_term

__all__ = [
    "power_exponent",
    "rotation_basis",
    "spectral_findings",
    "SHEAR_VARIANTS",
    "shear_term_fit",
    "shear_term_findings",
]


def power_exponent(model: Any) -> Optional[float]:
    """Q of the model's eigenvalue power sum tr C^q (Ogden: alpha / 2), or None."""
    alpha = getattr(model, "alpha", None)
    if type(model).__name__ != "Ogden" or not isinstance(alpha, (int, float)) or alpha == 0:
        return None
    return 0.5 * float(alpha)


def rotation_basis(points, cells, x, q: float) -> np.ndarray:
    """(m, 12, 12): V0 sym(F^T grad v) : X : sym(F^T grad w) per cell, X the divided-difference
    part of d(tr C^q)'s second derivative (module docstring); equal eigenvalues take the limit
    f'(lambda).
    """
    V0, D, F = cell_kinematics(points, cells, x)
    lam, N = np.linalg.eigh(F.swapaxes(1, 2) @ F)
    f = q * lam ** (q - 1.0)
    df = q * (q - 1.0) * lam ** (q - 2.0)
    gap = lam[:, :, None] - lam[:, None, :]
    close = np.abs(gap) <= 1e-8 * np.abs(lam).max(axis=1)[:, None, None]
    theta = np.where(
        close, df[:, :, None], (f[:, :, None] - f[:, None, :]) / np.where(close, 1, gap)
    )
    theta = theta * (1.0 - np.eye(3))  # i != j only
    X = 0.5 * (
        np.einsum("mij,mpi,mqj,mri,msj->mpqrs", theta, N, N, N, N)
        + np.einsum("mij,mpi,mqj,mrj,msi->mpqrs", theta, N, N, N, N)
    )
    X = 0.5 * (X + X.swapaxes(1, 2))
    K = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, X, F, D)
    return (V0[:, None, None, None, None] * K).reshape(-1, 12, 12)


def power_sum_slope(S: np.ndarray, F: np.ndarray, q: float) -> Optional[np.ndarray]:
    """(m,) dW/dP per cell of a law W(P, J), P = tr C^q, read from the oracle's per-cell stress
    S (m, 3, 3) = 2 dW/dP q C^(q-1) + dW/dJ J C^-1 (two unknowns on the eigenvalues; C need
    not have three distinct ones); None where S is not of that form or C is isotropic.
    """
    lam, N = np.linalg.eigh(F.swapaxes(1, 2) @ F)
    Se = np.einsum("mpi,mpq,mqj->mij", N, S, N)
    M = np.stack([2.0 * q * lam ** (q - 1.0), np.linalg.det(F)[:, None] / lam], axis=2)
    G = np.einsum("mia,mib->mab", M, M)
    if np.any(np.abs(np.linalg.det(G)) <= 1e-12 * np.einsum("maa->m", G) ** 2):
        return None
    y = np.einsum("mii->mi", Se)
    sol = np.linalg.solve(G, np.einsum("mia,mi->ma", M, y)[..., None])[..., 0]
    left = np.linalg.norm(Se - np.einsum("mi,ij->mij", np.einsum("mia,ma->mi", M, sol), np.eye(3)))
    if left > 1e-8 * np.linalg.norm(S):
        return None
    return sol[:, 0]


def _fourth(n: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) n (x) n (x) n (x) n of vectors n (m, 3)."""
    return np.einsum("mp,mq,mr,ms->mpqrs", n, n, n, n)


def in_plane_bases(points, cells, x, q: float) -> Tuple[np.ndarray, np.ndarray]:
    """(bases (m, 2, 12, 12), degenerate (m,) booleans). Where two eigenvalues of C are equal
    the engine's eigenvectors n1, n2 in their plane are any (its round-off chooses them, turned
    by phi from these), and the terms it keeps there, f' (n1^4 + n2^4), turn with them as
    P0 + cos 4 phi P1 + sin 4 phi P2: the bases are V0 BL : f' P1 : BL and V0 BL : f' P2 : BL.
    """
    V0, D, F = cell_kinematics(points, cells, x)
    lam, N = np.linalg.eigh(F.swapaxes(1, 2) @ F)
    gap = np.abs(np.diff(lam, axis=1))  # sorted: the pairs (0, 1) and (1, 2)
    close = gap <= 1e-8 * np.abs(lam).max(axis=1)[:, None]
    degenerate = close.any(axis=1)
    i = np.where(close[:, 0], 0, 1)
    m = np.arange(cells.shape[0])
    na, nb = N[m, :, i], N[m, :, i + 1]
    dfp = q * (q - 1.0) * lam[m, i] ** (q - 2.0) * degenerate

    def g(phi):
        c, s_ = np.cos(phi), np.sin(phi)
        return _fourth(c * na + s_ * nb) + _fourth(c * nb - s_ * na)

    g0, g4, g8 = g(0.0), g(np.pi / 4), g(np.pi / 8)
    out = []
    for T in (0.5 * (g0 - g4), g8 - 0.5 * (g0 + g4)):
        K = np.einsum(
            "maI,mkJ,mJIML,mlM,mbL->makbl", D, F, dfp[:, None, None, None, None] * T, F, D
        )
        out.append((V0[:, None, None, None, None] * K).reshape(-1, 12, 12))
    return np.stack(out, axis=1), degenerate


def _fit(cells, q, points, x, D, K_o, slope):
    """(residual, coefficients of the X basis per cell): one unknown per cell; in cells with
    two equal eigenvalues the X part's coefficient is the known -4 dW/dP (``slope``) and the
    two in-plane turns are fitted instead (None: no such cells may be fitted).
    """
    X = rotation_basis(points, cells, x, q)
    bases, degenerate = in_plane_bases(points, cells, x, q)
    if not degenerate.any():
        return fit_cell_term(cells, X, D, K_o)
    if slope is None:
        return np.inf, np.zeros(cells.shape[0])
    from conformance.diagnosis.elements import assemble

    known = np.where(degenerate, -4.0 * slope, 0.0)
    zero = np.zeros((cells.shape[0], 4, 3))
    D = (D - assemble(cells, points.shape[0], zero, known[:, None, None] * X)[1]).tocsr()
    free = np.concatenate([X[~degenerate], bases[degenerate].reshape(-1, 12, 12)])
    owners = np.concatenate([cells[~degenerate], np.repeat(cells[degenerate], 2, axis=0)])
    residual, u = fit_cell_term(owners, free, D, K_o)
    known[~degenerate] = u[: int((~degenerate).sum())]
    return residual, known


def spectral_findings(
    model: Any,
    points,
    cells,
    x,
    K: sp.spmatrix,
    K_o: sp.spmatrix,
    tol: float,
    S: Optional[np.ndarray] = None,
) -> List[Finding]:
    """The coaxial-tangent finding when the per-cell fit explains K - K_o within ``tol``;
    S: the oracle's per-cell stress (m, 3, 3), needed where C has two equal eigenvalues.
    """
    q = power_exponent(model)
    if q is None:
        return []
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    slope = None
    if S is not None:
        slope = power_sum_slope(S, cell_kinematics(points, cells, x)[2], q)
    residual, lam = _fit(cells, q, points, x, D, K_o, slope)
    if residual > tol:
        return []
    p = np.percentile(lam, [0, 50, 100])
    return [
        Finding(
            "tangent-coaxial",
            "coaxial tangent: the derivative of C^(alpha/2 - 1) taken with the eigenvectors "
            "held fixed (the divided differences between the eigenvalues, the rotation of the "
            "principal directions, dropped from your tangent)",
            FULL,
            "K - K_oracle = sum over cells of c_c V0 BL : X : BL, X the divided-difference "
            f"part of d2(tr C^{q:g})/dC2, leaves a stiffness error of {residual:.1e}; c_c "
            f"from {p[0]:.4g} to {p[2]:.4g} Pa, median {p[1]:.4g} (fitted; where C has two "
            "equal eigenvalues, -4 dW/dP from the oracle's stress, with the turn of the "
            "engine's eigenvectors in their plane fitted); the force matches",
            {"residual": residual, "coefficient_median": float(p[1])},
        )
    ]


# ------------------------------------------------------------------ the shear terms' factor
#: code -> (words, the part of the spectral tangent whose a != b (shear) terms the engine
#: writes wrong: "isochoric" (the whole isochoric tangent, as a spectral routine returns it)
#: or "fictitious" (the fictitious tangent's divided differences, before the projection),
#: the engine's factor on that part's terms per pair of isochoric stretches (a, b) (m, 3, 3)).
SHEAR_VARIANTS = {
    "shear-sign": (
        "the off-diagonal (a != b, shear) terms of the spectral tangent with the wrong sign: "
        "the numerator of their divided difference written the other way round (b's stress "
        "term before a's) over lambda_a^2 - lambda_b^2",
        "isochoric",
        lambda la, lb: -np.ones_like(la * lb),
    ),
    "shear-sign-fictitious": (
        "the off-diagonal (a != b, shear) terms of the fictitious spectral tangent "
        "(S_b - S_a) / (lambda_b^2 - lambda_a^2) with the wrong sign (numerator reversed)",
        "fictitious",
        lambda la, lb: -np.ones_like(la * lb),
    ),
    "shear-stretches": (
        "the off-diagonal (a != b, shear) terms of the spectral tangent divided by the "
        "difference of the stretches, (S_b - S_a) / (lambda_b - lambda_a), where the "
        "difference of their squares, lambda_b^2 - lambda_a^2, belongs (Holzapfel 6.196)",
        "fictitious",
        lambda la, lb: la + lb,
    ),
}


def _spatial_element(c4: np.ndarray, v: np.ndarray, gN: np.ndarray) -> np.ndarray:
    """(m, 12, 12) element stiffness v g_a . c4 . g_b of per-cell tensors c4 (m, 3, 3, 3, 3),
    weights v (m,) and spatial gradients gN (m, 4, 3).
    """
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", v, gN, c4, gN, optimize=True)
    return Ke.reshape(-1, 12, 12)


def _turn_words(turned: int, rest: str) -> str:
    """How a prediction was made: nothing fitted, or the in-plane turns of ``turned`` cells."""
    if not turned:
        return " (nothing fitted)"
    return (
        f" ({turned} cells with two equal stretches: the turn of your engine's eigenvectors in "
        f"their plane fitted, two numbers a cell; {rest})"
    )


#: code -> (words, the shift of every pair's shear coefficient (Kirchhoff) per cell from
#: mu / alpha (the model's) and the isochoric stretches' sum of powers S = sum lambda_bar^alpha):
#: a term of the coefficient written with the wrong sign adds twice itself.
SHEAR_SHIFTS = {
    "shear-mean-sign": (
        "the off-diagonal (a != b, shear) coefficient (tau_a lambda_b^2 - tau_b lambda_a^2) / "
        "(lambda_a^2 - lambda_b^2) expanded with the deviatoric mean's term -mu/(3 alpha) "
        "sum lambda_bar^alpha where + belongs (the sign of the mean in tau_a = mu/alpha "
        "(lambda_bar_a^alpha - sum/3) lost)",
        lambda k, S: -2.0 * k * S / 3.0,
    ),
}


def _pair_tensors(n: np.ndarray, a: int, b: int) -> tuple:
    """(s (x) s, u, w) of the principal pair (a, b): s = w = n_a n_b + n_b n_a and
    u = n_a n_a - n_b n_b (m, 3, 3), n (m, 3, 3) the principal directions as columns.
    """
    na, nb = n[:, :, a], n[:, :, b]
    w = np.einsum("mi,mj->mij", na, nb) + np.einsum("mi,mj->mij", nb, na)
    u = np.einsum("mi,mj->mij", na, na) - np.einsum("mi,mj->mij", nb, nb)
    return np.einsum("mij,mkl->mijkl", w, w), u, w


def shear_term_fit(model: Any, split, D: sp.csr_matrix, K_o: sp.csr_matrix, code: str):
    """(residual ||D - prediction|| / ||K_o||, degenerate cells) of :data:`SHEAR_VARIANTS`'
    ``code``: per cell, in the principal frame n_a of b, the shear coefficients of the
    oracle's Kirchhoff tangent J c, g_ab = (n_a n_b) : J c : (n_a n_b) + J U' (its volumetric
    -2 J U' II taken out, J U' = tr(tau) / 3), less tr(tau_bar) / 3 = mu / (3 alpha) sum
    lambda_bar^alpha for the fictitious part; the engine's K = K_o + sum over pairs of
    v grad N . (phi_ab - 1) g_ab (s (x) s) / J . grad N. Where two stretches are equal the
    engine's frame in their plane is its round-off's: there the pair's s (x) s turns as
    T0 + cos 4 psi T1 + sin 4 psi T2 and the two turns are fitted per cell. None: not an
    Ogden model, or a cell with three equal stretches.
    """
    from conformance.diagnosis.elements import assemble, cell_piola
    from conformance.diagnosis.invariant_pieces import cell_tensors
    from conformance.diagnosis.spatial_tangent import spatial_cells

    q = power_exponent(model)
    if q is None:
        return None
    if code in SHEAR_SHIFTS:
        shift = SHEAR_SHIFTS[code][1]
        part, factor = "isochoric", lambda la, lb: np.ones_like(la * lb)
    else:
        (_, part, factor), shift = SHEAR_VARIANTS[code], None
    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    sc = spatial_cells(split, t.S, t.CC)
    J = np.linalg.det(split.F)
    Jc = J[:, None, None, None, None] * sc.c
    tau = J[:, None, None] * sc.sigma
    x, n = np.linalg.eigh(split.F @ split.F.swapaxes(1, 2))
    xb = J[:, None] ** (-2.0 / 3.0) * x
    close = np.abs(x[:, :, None] - x[:, None, :]) <= 1e-8 * x.max(axis=1)[:, None, None]
    if np.any(close[:, 0, 1] & close[:, 1, 2]):
        return None
    sub = np.trace(tau, axis1=1, axis2=2) / 3.0  # J U'
    if part == "fictitious":
        sub = sub - float(model.mu) / (3.0 * 2.0 * q) * np.sum(xb**q, axis=1)
    phi = factor(np.sqrt(xb)[:, :, None], np.sqrt(xb)[:, None, :])
    m = J.size
    known = np.zeros_like(Jc)
    turns, owners = [], []
    for a, b in ((0, 1), (0, 2), (1, 2)):
        ss, u, w = _pair_tensors(n, a, b)
        g = np.einsum("mij,mijkl,mkl->m", w, Jc, w) / 4.0 + sub
        if shift is None:
            coef = ((phi[:, a, b] - 1.0) * g)[:, None, None, None, None]
        else:
            k = float(model.mu) / (2.0 * q)  # mu / alpha
            coef = shift(k, np.sum(xb**q, axis=1))[:, None, None, None, None]
        deg = close[:, a, b]
        uu, ww = np.einsum("mij,mkl->mijkl", u, u), np.einsum("mij,mkl->mijkl", w, w)
        uw = np.einsum("mij,mkl->mijkl", u, w)
        T0 = 0.5 * (uu + ww)
        known = known + coef * np.where(deg[:, None, None, None, None], T0, ss)
        for T in (0.5 * (ww - uu), -0.5 * (uw + uw.transpose(0, 3, 4, 1, 2))):
            turns.append((coef * T)[deg])
            owners.append(np.flatnonzero(deg))

    zero = np.zeros((m, 4, 3))
    Kd = assemble(split.cells, split.n, zero, _spatial_element(known, sc.v / J, sc.gN))[1]
    R = (D - Kd).tocsr()
    own = np.concatenate(owners)
    if own.size == 0:
        return float(sparse_norm(R)) / float(sparse_norm(K_o)), 0
    basis = _spatial_element(np.concatenate(turns), (sc.v / J)[own], sc.gN[own])
    residual, _ = fit_cell_term(split.cells[own], basis, R, K_o)
    return residual, int(np.unique(own).size)


def shear_term_findings(model: Any, split, K: sp.spmatrix, K_o: sp.spmatrix, tol: float):
    """The findings of :data:`SHEAR_VARIANTS` whose prediction (:func:`shear_term_fit`) leaves
    the stiffness within ``tol`` ([] for another model, or none within).
    """
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    found = []
    codes = [(c, w, p) for c, (w, p, _) in SHEAR_VARIANTS.items()]
    codes += [(c, w, "isochoric") for c, (w, _) in SHEAR_SHIFTS.items()]
    for code, words, part in codes:
        fit = shear_term_fit(model, split, D, K_o, code)
        if fit is None or not fit[0] <= tol:
            continue
        residual, turned = fit
        found.append(
            Finding(
                f"tangent-{code}",
                f"Ogden's spectral tangent: {words} (stiffness only)",
                FULL,
                "the oracle's Kirchhoff tangent J c per cell in the principal frame of b, its "
                f"{part} part's a != b coefficients (the volumetric -2 J U' II taken out, "
                "J U' = tr(tau)/3"
                + (", and tr(tau_bar)/3 of the projection" if part == "fictitious" else "")
                + ") given that factor, the rest kept: stiffness error against your engine "
                f"{residual:.1e}"
                + _turn_words(turned, "the other pairs predicted with nothing fitted")
                + "; the force matches",
                {"variant": code, "residual": residual, "turned_cells": turned},
            )
        )
    return found


# ------------------------------------------------------------------ the -2 tau_a n_a^4 term
#: factor on the term as written -> words (the engine writes (1 + factor) times the term).
STRESS_TERM_FACTORS = {
    -1.0: "left out",
    -2.0: "with its sign flipped",
    -0.5: "halved",
    1.0: "doubled",
}


def stress_term_fit(split, D: sp.csr_matrix, K_o: sp.csr_matrix, factor: float):
    """(residual ||D - prediction|| / ||K_o||, cells turned) of a spectral engine whose Kirchhoff
    tangent carries ``factor`` times a further -2 sum_a tau_a n_a^4, tau_a the principal values
    of the deviatoric Kirchhoff stress dev(J sigma) (the isochoric stress of a decoupled law;
    its volumetric -2 J p II is written apart), n_a the principal directions of b. Where two
    stretches are equal the engine's pair (n_a, n_b) in their plane is its round-off's, turned
    by psi from the oracle's: n_a^4 + n_b^4 = E + (u u + w w) / 4 + cos 4 psi (u u - w w) / 4 +
    sin 4 psi (u w + w u) / 4 (u = n_a n_a - n_b n_b, w = n_a n_b + n_b n_a), and cos 4 psi, sin
    4 psi are fitted per cell as two free numbers (the assembled stiffness does not fix each
    cell's turn apart from its neighbours', so they are not asked to lie on the unit circle);
    the third direction and the plane's turn-free part are predicted. None: three equal
    stretches.
    """
    from conformance.diagnosis.elements import assemble, cell_piola
    from conformance.diagnosis.invariant_pieces import cell_tensors
    from conformance.diagnosis.spatial_tangent import spatial_cells

    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    sc = spatial_cells(split, t.S, t.CC)
    J = np.linalg.det(split.F)
    tau = J[:, None, None] * sc.sigma
    tau = tau - np.trace(tau, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
    x, n = np.linalg.eigh(split.F @ split.F.swapaxes(1, 2))
    close = np.abs(np.diff(x, axis=1)) <= 1e-8 * x.max(axis=1)[:, None]
    if np.any(close.all(axis=1)):
        return None
    t_a = np.einsum("mia,mij,mja->ma", n, tau, n)
    coef = -2.0 * factor * t_a  # the engine's extra -2 factor tau_a n_a^4
    known = np.einsum("ma,mpa,mqa,mra,msa->mpqrs", coef, n, n, n, n)
    deg = close.any(axis=1)
    a = np.where(close[:, 0], 0, 1)
    m = np.arange(J.size)
    na, nb = n[m, :, a], n[m, :, a + 1]
    u = np.einsum("mi,mj->mij", na, na) - np.einsum("mi,mj->mij", nb, nb)
    w = np.einsum("mi,mj->mij", na, nb) + np.einsum("mi,mj->mij", nb, na)
    uu, ww = np.einsum("mij,mkl->mijkl", u, u), np.einsum("mij,mkl->mijkl", w, w)
    uw = np.einsum("mij,mkl->mijkl", u, w)
    c_pair = coef[m, a][:, None, None, None, None] / 4.0
    turns = [c_pair * (uu - ww), c_pair * (uw + uw.transpose(0, 3, 4, 1, 2))]

    zero = np.zeros((J.size, 4, 3))
    Kd = assemble(split.cells, split.n, zero, _spatial_element(known, sc.v / J, sc.gN))[1]
    R = (D - Kd).tocsr()
    if not deg.any():
        return float(sparse_norm(R)) / float(sparse_norm(K_o)), 0
    own = np.flatnonzero(deg)
    basis = np.concatenate(
        [_spatial_element(T[own], (sc.v / J)[own], sc.gN[own]) for T in turns]
    )  # (2 k, 12, 12): the cos parts, then the sin parts
    owners = np.concatenate([split.cells[own], split.cells[own]])
    residual, _ = fit_cell_term(owners, basis, R, K_o)
    return residual, own.size


def stress_term_findings(model: Any, split, K: sp.spmatrix, K_o: sp.spmatrix, tol: float):
    """The -2 tau_a n_a^4 term of a spectral (Bonet and Wood) spatial tangent taken with one of
    :data:`STRESS_TERM_FACTORS` (:func:`stress_term_fit`), for an isotropic law, when its
    prediction leaves the stiffness within ``tol``; [] else.
    """
    from conformance.diagnosis.principal_blocks import principal_frame_isotropic

    if not principal_frame_isotropic(split):
        return []
    K_o = sp.csr_matrix(K_o)
    D = (sp.csr_matrix(K) - K_o).tocsr()
    found = []
    for factor, said in STRESS_TERM_FACTORS.items():
        fit = stress_term_fit(split, D, K_o, factor)
        if fit is None or not fit[0] <= tol:
            continue
        residual, turned = fit
        found.append(
            Finding(
                "tangent-spectral-stress-term",
                "a spectral tangent's term -2 sigma_a n_a (x) n_a (x) n_a (x) n_a (Bonet and "
                "Wood's spatial form, beside 1/J d tau_a / d ln lambda_b n_a n_a n_b n_b; "
                f"sigma_a the isochoric principal Cauchy stresses) {said} (stiffness only)",
                FULL,
                "the oracle's Kirchhoff tangent per cell plus that change of the term, from the "
                "oracle's deviatoric stress in the principal frame of b: stiffness error "
                f"against your engine {residual:.1e}"
                + _turn_words(turned, "the third direction predicted")
                + "; the force matches",
                {"factor": factor, "residual": residual, "turned_cells": turned},
            )
        )
    return found
