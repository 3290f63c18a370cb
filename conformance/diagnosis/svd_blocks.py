"""A tangent dP/dF written in the SVD basis by Teran et al.'s blocks, with one piece wrong.

Invertible-FEM and graphics codes (Irving, Teran and Fedkiw 2004; Teran et al. 2005; Sifakis
and Barbic 2012) take the rotation-variant SVD F = U diag(sigma) V^T (det U = det V = 1),
write an isotropic energy as Psi(sigma), its stress P = U diag(psi) V^T, psi_i = dPsi/dsigma_i,
and its tangent in the SVD basis, Ahat_abcd = U_ia V_Jb U_kc V_Ld A_iJkL (A_iJkL = dP_iJ/dF_kL),
by blocks:

- the 3x3 block Ahat_iijj = H_ij = d2Psi/dsigma_i dsigma_j;
- per pair i < j a 2x2 block Ahat_ijij = Ahat_jiji = a, Ahat_ijji = Ahat_jiij = b with
  a = (minus + plus) / 2, b = (minus - plus) / 2, minus = (psi_i - psi_j)/(sigma_i - sigma_j)
  (its limit H_ii - H_ij where sigma_i = sigma_j) and plus = (psi_i + psi_j)/(sigma_i + sigma_j).

Here the oracle's per-cell P and A (:func:`conformance.diagnosis.elements.cell_piola`, from the
element split) are rotated into that basis and read as these pieces (psi = diag(U^T P V)); the
read is trusted only where the rotated A has the block structure (an isotropic material). Two
readings, neither fitting anything beyond what it declares:

1. **The pieces' coefficients** (:func:`piece_fit`, on states where no two singular values are
   equal): the engine's stiffness fitted over the case as a combination of six pieces'
   stiffnesses V0 G^T A_piece G, A_piece the piece rotated back: the 3x3 block's diagonal
   (d2Psi/dsigma_i^2), its off-diagonal (the mixed d2Psi/dsigma_i dsigma_j), and of the 2x2
   blocks the minus part (minus/2 on the a and b entries) and the plus part (plus/2 on a,
   -plus/2 on b), each for the (i, j) and the (j, i) entries apart. The fit is refused when the
   pieces are not separated (:func:`conformance.diagnosis.least_squares.determined_lstsq`); the
   pieces whose coefficient is not 1 are named (plus -1: a and b exchanged; the (j, i) entries
   0: one ordering of each pair written), once the force is the oracle's and the stiffness so
   rebuilt is within the tolerance.
2. **Predicted variants** (:data:`VARIANTS`), each the engine's blocks computed from the
   oracle's: the coefficient patterns above (2x2 blocks doubled, a and b exchanged, one
   ordering, the 3x3 block's diagonal alone), and three that are not linear in the pieces: the
   plus quotient written with psi_i - psi_j, Teran's definiteness fix left on (the negative
   eigenvalues of the 3x3 block and of each 2x2 block, minus and plus, clamped to zero), and
   the minus quotient taken literally with its denominator clamped where two singular values
   are equal (there ~0 instead of its limit).

**Equal singular values** (the uniaxial state): where sigma_p = sigma_q the engine's U and V
columns p, q are any pair turned by one angle phi in their plane (its round-off chooses), and
a wrong block is not invariant under that turn. There a variant's tensor, rotated back, is
T0 + cos 2 phi T2c + sin 2 phi T2s + cos 4 phi T4c + sin 4 phi T4s (a fourth-order tensor's
harmonics, computed by sampling phi). A variant is dropped at once when even free numbers for
the harmonics leave more than ten times the tolerance; else the numbers' least-squares fit
(:func:`conformance.diagnosis.second_derivative.fit_cell_term`) gives a first phi per cell,
Gauss-Newton steps on phi (one unknown a cell) refine it, and where they stall the fit's null
space is searched for numbers that are an angle's (Levenberg-Marquardt on those conditions).
The variant's stiffness rebuilt with the phi found must then be within the tolerance: one
angle per cell, nothing else. The piece fit is not tried there (its pieces depend on phi).
Three equal singular values (rest) claim nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    cell_piola,
    prediction_errors,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.diagnosis.least_squares import determined_lstsq
from conformance.diagnosis.singular_value_pieces import PAIRS, rotation_variant_svd
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "PAIRS",
    "TeranBlocks",
    "teran_blocks",
    "block_tensor",
    "Blocks",
    "VARIANTS",
    "PIECES",
    "variant_output",
    "piece_fit",
    "svd_block_findings",
    "svd_block_reading",
]


#: Two singular values closer than this (relative to the largest) are equal: the frame turns.
_EQUAL = 1e-8
#: Largest departure (relative) of the oracle's rotated tangent from the block structure.
_STRUCTURE = 1e-8
#: A coefficient this far from 1 is a piece written wrongly.
_OFF = 1e-3
#: Gauss-Newton steps on the turn angles (at most).
_NEWTON = 40
#: Most harmonics' numbers (columns) read with a dense SVD of the fit (:func:`_unit_numbers`).
_DENSE = 2500
#: The sizes of the perturbed starts of the search (8 of each), in the numbers' RMS change.
_RESTARTS = (0.1, 0.3, 0.6)
#: The angle conditions met to this (the data's round-off, e.g. a clamped quotient's, leaves
#: more than machine precision; the rebuilt stiffness is judged against the tolerance after).
_MET = 1e-6


@dataclass(frozen=True)
class Blocks:
    """Teran's blocks of a tangent in the SVD basis: H (m, 3, 3) the 3x3 block; per pair of
    :data:`PAIRS` (columns n) the entries a_ij = Ahat_ijij, a_ji = Ahat_jiji, b_ij = Ahat_ijji,
    b_ji = Ahat_jiij (m, 3).
    """

    H: np.ndarray
    a_ij: np.ndarray
    a_ji: np.ndarray
    b_ij: np.ndarray
    b_ji: np.ndarray


@dataclass(frozen=True)
class TeranBlocks:
    """The oracle's tangent read as Teran's blocks: U, sigma, V (:func:`rotation_variant_svd`); psi
    (m, 3) = diag(U^T P V); blocks; minus, plus (m, 3) per pair (a + b, a - b); equal (m, 3)
    per pair: its singular values equal (the frame turns in their plane); structure: how far
    the rotated tangent is from the block structure (relative).
    """

    U: np.ndarray
    sigma: np.ndarray
    V: np.ndarray
    psi: np.ndarray
    blocks: Blocks
    minus: np.ndarray
    plus: np.ndarray
    equal: np.ndarray
    structure: float


def block_tensor(b: Blocks) -> np.ndarray:
    """Ahat (m, 3, 3, 3, 3) holding the blocks ``b`` (zero elsewhere)."""
    m = b.H.shape[0]
    Ah = np.zeros((m, 3, 3, 3, 3))
    for i in range(3):
        for j in range(3):
            Ah[:, i, i, j, j] = b.H[:, i, j]
    for n, (i, j) in enumerate(PAIRS):
        Ah[:, i, j, i, j] += b.a_ij[:, n]
        Ah[:, j, i, j, i] += b.a_ji[:, n]
        Ah[:, i, j, j, i] += b.b_ij[:, n]
        Ah[:, j, i, i, j] += b.b_ji[:, n]
    return Ah


def _rotate_back(U: np.ndarray, V: np.ndarray, Ah: np.ndarray) -> np.ndarray:
    """A_iJkL = U_ia V_Jb U_kc V_Ld Ahat_abcd (m, 3, 3, 3, 3)."""
    return np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", U, V, U, V, Ah, optimize=True)


def teran_blocks(P: np.ndarray, A: np.ndarray, F: np.ndarray) -> TeranBlocks:
    """The oracle's P (m, 3, 3) and A (m, 3, 3, 3, 3) read in the SVD basis of F (m, 3, 3)."""
    U, s, V = rotation_variant_svd(F)
    Ah = np.einsum("mia,mjb,mkc,mld,mijkl->mabcd", U, V, U, V, A, optimize=True)
    psi = np.einsum("mia,mij,mja->ma", U, P, V)
    H = np.einsum("maacc->mac", Ah)
    i, j = (np.array(t) for t in zip(*PAIRS))
    b = Blocks(H, Ah[:, i, j, i, j], Ah[:, j, i, j, i], Ah[:, i, j, j, i], Ah[:, j, i, i, j])
    left = np.linalg.norm(Ah - block_tensor(b)) / max(np.linalg.norm(Ah), 1e-300)
    a = 0.5 * (b.a_ij + b.a_ji)
    bb = 0.5 * (b.b_ij + b.b_ji)
    scale = np.abs(s).max(axis=1, keepdims=True)
    equal = np.abs(s[:, i] - s[:, j]) <= _EQUAL * scale
    return TeranBlocks(U, s, V, psi, b, a + bb, a - bb, equal, float(left))


def _from_quotients(minus: np.ndarray, plus: np.ndarray, H: np.ndarray) -> Blocks:
    """The blocks of Teran's formulas from the two quotients per pair and the 3x3 block."""
    a, b = 0.5 * (minus + plus), 0.5 * (minus - plus)
    return Blocks(H, a, a, b, b)


def _pair_columns(t: TeranBlocks, x: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(x_i, x_j) (m, 3) per pair of :data:`PAIRS` of a per-cell (m, 3) array."""
    i, j = (list(t_) for t_ in zip(*PAIRS))
    return x[:, i], x[:, j]


def _plus_difference(t: TeranBlocks) -> Blocks:
    si, sj = _pair_columns(t, t.sigma)
    pi, pj = _pair_columns(t, t.psi)
    return _from_quotients(t.minus, (pi - pj) / (si + sj), t.blocks.H)


def _definite(t: TeranBlocks) -> Blocks:
    lam, Q = np.linalg.eigh(t.blocks.H)
    H = np.einsum("mia,ma,mja->mij", Q, np.maximum(lam, 0.0), Q)
    return _from_quotients(np.maximum(t.minus, 0.0), np.maximum(t.plus, 0.0), H)


def _gap_clamped(t: TeranBlocks) -> Blocks:
    pi, pj = _pair_columns(t, t.psi)
    si, sj = _pair_columns(t, t.sigma)
    gap = si - sj
    literal = (pi - pj) / np.where(gap == 0.0, 1.0, gap)
    clamped = np.where(t.equal, 0.0, literal)  # round-off over the clamp: ~0
    return _from_quotients(np.where(t.equal, clamped, t.minus), t.plus, t.blocks.H)


def _scaled(t: TeranBlocks, hd=1.0, ho=1.0, mij=1.0, mji=1.0, pij=1.0, pji=1.0) -> Blocks:
    """The blocks with the pieces (:data:`PIECES`) scaled by these coefficients."""
    H = t.blocks.H
    d = np.einsum("mii->mi", H)
    Hs = ho * H + (hd - ho) * np.einsum("mi,ij->mij", d, np.eye(3))
    half_m, half_p = 0.5 * t.minus, 0.5 * t.plus
    return Blocks(
        Hs,
        mij * half_m + pij * half_p,
        mji * half_m + pji * half_p,
        mij * half_m - pij * half_p,
        mji * half_m - pji * half_p,
    )


_QUOTIENTS = (
    "minus = (psi_i - psi_j)/(sigma_i - sigma_j), plus = (psi_i + psi_j)/(sigma_i + sigma_j)"
)
_BLOCKS = (
    "Teran's 2x2 blocks of dP/dF in the SVD basis (F = U diag(sigma) V^T, psi_i = dPsi/dsigma_i"
)

#: code -> (words, the engine's blocks from the oracle's).
VARIANTS: Dict[str, Tuple[str, Callable[[TeranBlocks], Blocks]]] = {
    "blocks-doubled": (
        f"{_BLOCKS}) doubled: a = minus + plus, b = minus - plus written without the 1/2 of "
        f"a = (minus + plus)/2, b = (minus - plus)/2 ({_QUOTIENTS}); the rotational part of the "
        "tangent twice too large (stiffness only); in an analytic eigensystem's words, the same "
        "slip: the twist and flip modes U (e_i e_j^T -+ e_j e_i^T) V^T used without their "
        "1/sqrt(2) normalisation (their eigenvalues plus and minus counted twice)",
        lambda t: _scaled(t, mij=2.0, mji=2.0, pij=2.0, pji=2.0),
    ),
    "entries-exchanged": (
        f"the entries a and b of {_BLOCKS}) exchanged: each block [[b, a], [a, b]] for "
        f"[[a, b], [b, a]], a = (minus + plus)/2, b = (minus - plus)/2 ({_QUOTIENTS}); the same "
        "as the plus quotient with the wrong sign (stiffness only)",
        lambda t: _scaled(t, pij=-1.0, pji=-1.0),
    ),
    "one-ordering": (
        f"{_BLOCKS}) written for one ordering of each pair only: Ahat_ijij = a and Ahat_ijji = "
        "b for i < j, the (j, i) entries Ahat_jiji and Ahat_jiij left zero (half of the block "
        "entries missing; stiffness only, K not symmetric)",
        lambda t: _scaled(t, mji=0.0, pji=0.0),
    ),
    "hessian-diagonal": (
        "only the diagonal d2Psi/dsigma_i^2 of the 3x3 block of dP/dF in the SVD basis (F = U "
        "diag(sigma) V^T): the mixed second derivatives d2Psi/dsigma_i dsigma_j (i != j, e.g. "
        "of the volumetric term) left out, as if the energy were separable sum_i f(sigma_i) "
        "(stiffness only)",
        lambda t: _scaled(t, ho=0.0),
    ),
    "plus-difference": (
        f"the plus quotient of {_BLOCKS}) written (psi_i - psi_j)/(sigma_i + sigma_j) where "
        "(psi_i + psi_j)/(sigma_i + sigma_j) belongs (the minus sign copied from the minus "
        "quotient (psi_i - psi_j)/(sigma_i - sigma_j); stiffness only)",
        _plus_difference,
    ),
    "definiteness-fix": (
        "Teran et al.'s definiteness fix left on in the tangent: the negative eigenvalues of "
        "the 3x3 block d2Psi/dsigma_i dsigma_j and of the 2x2 blocks (the minus and plus "
        f"quotients, {_QUOTIENTS}) of dP/dF in the SVD basis clamped to zero, so the stiffness "
        "is projected to positive semi-definite and is no longer the Hessian (stiffness only)",
        _definite,
    ),
    "gap-clamped": (
        "the minus quotient (psi_i - psi_j)/(sigma_i - sigma_j) of Teran's 2x2 blocks taken "
        "literally with its denominator clamped where two singular values are equal "
        "(sigma_i = sigma_j, a repeated singular value): there it is ~0 instead of its limit "
        "d2Psi/dsigma_i^2 - d2Psi/dsigma_i dsigma_j (l'Hopital; stiffness only)",
        _gap_clamped,
    ),
}

#: The pieces of the fit (:func:`piece_fit`), in order: words.
PIECES = (
    "the diagonal d2Psi/dsigma_i^2 of the 3x3 block",
    "the off-diagonal (mixed d2Psi/dsigma_i dsigma_j) of the 3x3 block",
    "the minus quotient's part of the 2x2 blocks' (i, j) entries",
    "the minus quotient's part of the 2x2 blocks' (j, i) entries",
    "the plus quotient's part of the 2x2 blocks' (i, j) entries",
    "the plus quotient's part of the 2x2 blocks' (j, i) entries",
)


def _element_matrices(split: ElementSplit, A: np.ndarray) -> np.ndarray:
    """V0 G_a A G_b (m, 12, 12) of per-cell tangents A (m, 3, 3, 3, 3)."""
    return tangent_element_matrices(split.V0, split.D, A)


def _turned(t: TeranBlocks, phi: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """U, V with the columns of each cell's (first) equal pair turned by phi (m,)."""
    U, V = t.U.copy(), t.V.copy()
    c, s_ = np.cos(phi), np.sin(phi)
    for n, (p, q) in enumerate(PAIRS):
        on = t.equal[:, n] & ~t.equal[:, :n].any(axis=1)
        for W, W0 in ((U, t.U), (V, t.V)):
            wp = c[:, None] * W0[:, :, p] + s_[:, None] * W0[:, :, q]
            wq = -s_[:, None] * W0[:, :, p] + c[:, None] * W0[:, :, q]
            W[on, :, p], W[on, :, q] = wp[on], wq[on]
    return U, V


def _harmonics(t: TeranBlocks, Ah: np.ndarray) -> np.ndarray:
    """(5, m, 3, 3, 3, 3): T0, T2c, T2s, T4c, T4s of the blocks Ah rotated back with the frame
    turned by phi in the equal pair's plane (exact: samples at k pi / 8, k < 8).
    """
    phis = np.arange(8) * np.pi / 8
    m = Ah.shape[0]
    samples = np.stack([_rotate_back(*_turned(t, np.full(m, f)), Ah) for f in phis])
    out = [samples.mean(axis=0)]
    for h in (2, 4):
        for trig in (np.cos, np.sin):
            w = trig(h * phis) * 2.0 / 8.0
            out.append(np.einsum("k,k...->...", w, samples))
    return np.stack(out)


def _unit_numbers(
    owners: np.ndarray, basis: np.ndarray, R: sp.csr_matrix, use: List[int], near: np.ndarray
) -> Optional[np.ndarray]:
    """The harmonics' numbers x (len(use), k) of the k turned cells that the stiffness error R
    asks for and that are an angle's (cos 2 phi, sin 2 phi, cos 4 phi, sin 4 phi: unit pairs,
    and the fourth harmonic the second's square): the least-squares solution of least norm
    moved in the null space of the assembled columns (dense SVD of ``basis`` (len(use) k, 12,
    12) scattered by ``owners``), from the point nearest the numbers ``near`` (len(use), k) and
    then from perturbed starts (:data:`_RESTARTS`, fixed seed), by Levenberg-Marquardt on those
    conditions; None when no start meets them.
    """
    N = R.shape[0]
    k = owners.shape[0] // len(use)
    dof = (3 * owners[:, :, None] + np.arange(3)).reshape(-1, 12)
    keys = (np.repeat(dof, 12, axis=1).astype(np.int64) * N + np.tile(dof, (1, 12))).ravel()
    pattern, where = np.unique(keys, return_inverse=True)
    A = np.zeros((pattern.size, owners.shape[0]))
    np.add.at(A, (where.ravel(), np.repeat(np.arange(owners.shape[0]), 144)), basis.ravel())
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1.0
    Us, sv, Vt = np.linalg.svd(A / norms, full_matrices=False)
    keep = sv > 1e-9 * sv[0]
    null = (Vt[~keep] / norms).T.reshape(len(use), k, -1)  # (len(use), k, r)
    Rc = sp.coo_matrix(R)
    rkeys = Rc.row.astype(np.int64) * N + Rc.col
    pos = np.minimum(np.searchsorted(pattern, rkeys), pattern.size - 1)
    inside = pattern[pos] == rkeys
    b = np.zeros(pattern.size)
    np.add.at(b, pos[inside], Rc.data[inside])
    x0 = ((Vt[keep].T @ ((Us[:, keep].T @ b) / sv[keep])) / norms).reshape(len(use), k)
    row = dict(zip(use, range(len(use))))

    def conditions(x: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(the conditions g (c, k), their derivatives by y (c, k, r)) at numbers x."""
        g, dg = [], []
        for pair in ((1, 2), (3, 4)):
            if pair[0] in row:
                p, q = row[pair[0]], row[pair[1]]
                g.append(x[p] ** 2 + x[q] ** 2 - 1.0)
                dg.append(2 * x[p][:, None] * null[p] + 2 * x[q][:, None] * null[q])
        if 1 in row and 3 in row:
            c2, s2, c4, s4 = (row[h] for h in (1, 2, 3, 4))
            g += [x[c4] - x[c2] ** 2 + x[s2] ** 2, x[s4] - 2 * x[c2] * x[s2]]
            dg += [
                null[c4] - 2 * x[c2][:, None] * null[c2] + 2 * x[s2][:, None] * null[s2],
                null[s4] - 2 * x[s2][:, None] * null[c2] - 2 * x[c2][:, None] * null[s2],
            ]
        return np.stack(g), np.stack(dg)

    flat = null.reshape(-1, null.shape[2])
    start = np.linalg.lstsq(flat, (near - x0).ravel(), rcond=None)[0]
    # perturbed starts (a few turns' worth, rho the RMS change of the numbers) out of the local
    # minima of the conditions
    unit = np.sqrt(flat.shape[0]) / max(float(np.linalg.norm(flat)), 1e-300)
    rng = np.random.default_rng(0)
    for rho in (0.0, *np.repeat(_RESTARTS, 8)):
        y = start + rho * unit * rng.standard_normal(start.size)
        x = _levenberg_marquardt(conditions, x0, null, y)
        if x is not None:
            return x
    return None


def _levenberg_marquardt(
    conditions: Callable, x0: np.ndarray, null: np.ndarray, y: np.ndarray
) -> Optional[np.ndarray]:
    """The numbers x0 + null y (null (len(use), k, r)) meeting ``conditions`` (x -> (g, dg/dy))
    by Levenberg-Marquardt from ``y``; None when they are not met.
    """
    g, dg = conditions(x0 + null @ y)
    now = float(np.sum(g**2))
    mu = 1e-3
    for _ in range(10 * _NEWTON):
        if np.abs(g).max() <= 1e-13 or not y.size:
            break
        J = dg.reshape(-1, y.size)
        JtJ = J.T @ J
        trial = y - np.linalg.solve(JtJ + mu * np.diag(np.diag(JtJ) + 1e-30), J.T @ g.ravel())
        g_t, dg_t = conditions(x0 + null @ trial)
        if float(np.sum(g_t**2)) < now:
            y, g, dg, now, mu = trial, g_t, dg_t, float(np.sum(g_t**2)), mu / 3.0
        else:
            mu *= 4.0
            if mu > 1e12:
                break
    return x0 + null @ y if np.abs(g).max() <= _MET else None


def _turn_angles(
    split: ElementSplit,
    Ke: np.ndarray,
    idx: np.ndarray,
    D: sp.csr_matrix,
    K_o: sp.csr_matrix,
    bound: float,
) -> Optional[np.ndarray]:
    """The turn angles phi (len(idx),) of the cells ``idx``; None when even free numbers for
    the harmonics (Ke (5, m, 12, 12): their element matrices) leave more than ``bound`` of
    D = K - K_o (relative to ||K_o||): not this variant. Else the free numbers' angles, then
    Gauss-Newton steps on phi alone (one unknown a cell, each step halved until the error
    falls); where they stall above round-off, the numbers made an angle's in the fit's null
    space (:func:`_unit_numbers`, cases of at most :data:`_DENSE` numbers) and Gauss-Newton
    again (the better of the two kept).
    """
    from conformance.diagnosis.second_derivative import fit_cell_term

    size = np.linalg.norm(Ke[:, idx].reshape(5, -1), axis=1)
    use = [h for h in range(1, 5) if size[h] > 1e-8 * max(size[0], 1e-300)]
    if not use:
        return np.zeros(idx.size)
    R = (D - assemble(split.cells, split.n, split.fe, Ke[0] - split.Ke)[1]).tocsr()
    basis = np.concatenate([Ke[h, idx] for h in use])
    owners = np.concatenate([split.cells[idx]] * len(use))
    free, lam = fit_cell_term(owners, basis, R, K_o)
    if not free <= bound:
        return None
    x0 = lam.reshape(len(use), -1)

    def angle(x: np.ndarray) -> np.ndarray:
        """The angles phi from the harmonics' numbers x (len(use), cells)."""
        got = dict(zip(use, x))
        if 1 in got:
            return 0.5 * np.arctan2(got[2], got[1])
        return 0.25 * np.arctan2(got[4], got[3])

    cells = split.cells[idx]

    def at(phi):
        """(element matrices of the turned cells, the stiffness error left) at ``phi``."""
        c2, s2, c4, s4 = (f(h * phi)[:, None, None] for h in (2, 4) for f in (np.cos, np.sin))
        K_i = Ke[0, idx] + c2 * Ke[1, idx] + s2 * Ke[2, idx] + c4 * Ke[3, idx] + s4 * Ke[4, idx]
        rest = Ke[0].copy()
        rest[idx] = K_i
        R = (D - assemble(split.cells, split.n, split.fe, rest - split.Ke)[1]).tocsr()
        dK = 2 * (c2 * Ke[2, idx] - s2 * Ke[1, idx]) + 4 * (c4 * Ke[4, idx] - s4 * Ke[3, idx])
        return dK, R

    scale = float(np.linalg.norm(D.data)) + float(np.linalg.norm(sp.csr_matrix(K_o).data))

    def newton(phi: np.ndarray) -> Tuple[np.ndarray, float]:
        """(phi, the error left) after Gauss-Newton steps from ``phi``."""
        dK, R = at(phi)
        left = float(np.linalg.norm(R.data))
        for _ in range(_NEWTON):
            step = fit_cell_term(cells, dK, R, K_o)[1]
            for _ in range(8):  # halve the step until the error falls
                dK_t, R_t = at(phi + step)
                left_t = float(np.linalg.norm(R_t.data))
                if left_t < left:
                    break
                step = 0.5 * step
            else:
                break
            phi, dK, R = phi + step, dK_t, R_t
            done = left_t > 0.999 * left or left_t <= 1e-13 * scale
            left = left_t
            if done:
                break
        return phi, left

    first, left = newton(angle(x0))
    if left <= 1e-13 * scale or basis.shape[0] > _DENSE:
        return first
    trig = (np.cos(2 * first), np.sin(2 * first), np.cos(4 * first), np.sin(4 * first))
    x = _unit_numbers(owners, basis, R, use, np.stack([trig[h - 1] for h in use]))
    if x is None:
        return first
    second, left_2 = newton(angle(x))
    return second if left_2 < left else first


def variant_output(
    split: ElementSplit,
    t: TeranBlocks,
    blocks: Blocks,
    D: sp.csr_matrix,
    K_o: sp.csr_matrix,
    bound: float = np.inf,
) -> Optional[Tuple[np.ndarray, sp.csr_matrix, int]]:
    """(force, stiffness, cells turned) of an engine whose blocks are ``blocks``: the oracle's
    force; where two singular values are equal the turn phi of the engine's frame read from the
    stiffness error D = K - K_o (:func:`_turn_angles`) and the stiffness built with it; None
    when free harmonics there leave more than ``bound`` (relative to ||K_o||).
    """
    Ah = block_tensor(blocks)
    turn = t.equal.any(axis=1)
    phi = np.zeros(t.sigma.shape[0])
    if turn.any():
        Ke = np.stack([_element_matrices(split, Th) for Th in _harmonics(t, Ah)])
        idx = np.flatnonzero(turn)
        got = _turn_angles(split, Ke, idx, D, K_o, bound)
        if got is None:
            return None
        phi[idx] = got
    U, V = _turned(t, phi)
    A = _rotate_back(U, V, Ah)
    f, K = assemble(split.cells, split.n, split.fe, _element_matrices(split, A))
    return f, K, int(turn.sum())


def piece_fit(
    split: ElementSplit, t: TeranBlocks, K: sp.spmatrix
) -> Optional[Tuple[np.ndarray, sp.csr_matrix]]:
    """(coefficients (6,) of :data:`PIECES`, the stiffness they rebuild) fitting the engine's K
    over the case; None where two singular values are equal or the pieces are not separated.
    """
    if t.equal.any():
        return None
    one = np.eye(6)
    Ks = []
    for row in one:
        A = _rotate_back(t.U, t.V, block_tensor(_scaled(t, *row)))
        Ks.append(assemble(split.cells, split.n, split.fe, _element_matrices(split, A))[1])
    pattern = sum(abs(k) for k in Ks) + abs(sp.csr_matrix(K))
    pattern = sp.csr_matrix(pattern)
    r, c = pattern.nonzero()
    cols = np.stack([np.asarray(k[r, c]).ravel() for k in Ks], axis=1)
    y = np.asarray(sp.csr_matrix(K)[r, c]).ravel()
    x = determined_lstsq(cols, y, 1e-6)
    if x is None:
        return None
    Kf = sp.csr_matrix(sum(float(xi) * k for xi, k in zip(x, Ks)))
    return x, Kf


def _piece_words(x: np.ndarray) -> str:
    """The pieces whose coefficients are not 1, in words (recognised patterns said plainly)."""
    off = np.abs(x - 1.0) > _OFF
    two = np.abs(x[2:] - 2.0) <= _OFF
    if not off[:2].any() and two.all():
        return VARIANTS["blocks-doubled"][0]
    said = [f"{PIECES[k]} times {x[k]:.4g}" for k in np.flatnonzero(off)]
    return (
        "dP/dF written in the SVD basis by Teran et al.'s blocks (F = U diag(sigma) V^T, psi_i "
        f"= dPsi/dsigma_i; {_QUOTIENTS}) with pieces wrong: " + "; ".join(said)
    )


def svd_block_findings(
    split: ElementSplit, f: np.ndarray, K: sp.spmatrix, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The variants of :data:`VARIANTS` (and the piece fit's reading, where it says something
    none of them says) whose force and stiffness match the engine's (several: ambiguous); none
    when the oracle's tangent is not of Teran's form, three singular values are equal, or the
    engine's force is not the oracle's.
    """
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    if not tol.within(errors(f, sp.csr_matrix(K0), None, f0, K0, 0.0, s), energy=False):
        return []  # these mistakes leave the force right
    with np.errstate(all="ignore"):
        t = teran_blocks(*cell_piola(split), split.F)
    if not t.structure <= _STRUCTURE or t.equal.all(axis=1).any():
        return []
    if np.any(t.equal[:, :2].all(axis=1)):  # two equal pairs in one cell: three equal values
        return []
    K = sp.csr_matrix(K)
    D = (K - K0).tocsr()
    bound = 10.0 * tol.stiffness * s.stiffness / float(np.linalg.norm(K0.data))
    found = []
    for code, (words, build) in VARIANTS.items():
        with np.errstate(all="ignore"):
            got = variant_output(split, t, build(t), D, sp.csr_matrix(K0), bound)
        if got is None:
            continue
        fv, Kv, turned = got
        e = prediction_errors(split, f, K, (fv, Kv), s, tol)
        if e is None:
            continue
        found.append(
            Finding(
                f"svd-blocks-{code}",
                words,
                FULL,
                "the oracle's P and dP/dF per cell (from its element split, whose sum is the "
                f"oracle's to {split.residual:.1e}) rotated into the SVD basis, its blocks "
                f"written so and rotated back: force error {e.force:.1e}, stiffness error "
                f"{e.stiffness:.1e}"
                + (
                    f" ({turned} cells with two equal singular values: the turn of your "
                    "engine's U and V in their plane read from the stiffness, one angle a cell)"
                    if turned
                    else ""
                ),
                {"variant": code, "residual": max(e.force, e.stiffness)},
            )
        )
    if not found:
        fit = piece_fit(split, t, K)
        if fit is not None:
            x, Kf = fit
            e = prediction_errors(split, f, K, (f0, Kf), s, tol)
            if e is not None and np.any(np.abs(x - 1.0) > _OFF):
                found.append(
                    Finding(
                        "svd-blocks-pieces",
                        _piece_words(x) + " (stiffness only)",
                        FULL,
                        "your stiffness fitted over the case as a combination of the pieces of "
                        "the oracle's dP/dF in the SVD basis (each rotated back and assembled): "
                        f"coefficients {', '.join(f'{v:.4g}' for v in x)} ("
                        + "; ".join(PIECES)
                        + f"); force error {e.force:.1e}, stiffness error {e.stiffness:.1e}",
                        {"coefficients": [float(v) for v in x]},
                    )
                )
    return ambiguous(found, "their blocks differ by less than the tolerance here")


def svd_block_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case, the force right, nothing named) with a wrong piece of Teran's
    SVD-basis tangent named first (:func:`conformance.diagnosis.elements.split_reading`).
    """
    from conformance.diagnosis.elements import split_reading

    return split_reading(diag, ci, out, ref, s, (svd_block_findings,))
