"""The engine's error read as the pieces of Holzapfel's isochoric/volumetric split.

Many biomechanics codes (FEBio's uncoupled materials, the textbook codes after Holzapfel,
Nonlinear Solid Mechanics, ch. 6) write a decoupled energy W = Psi(I1b, I2b) + U(J),
C_bar = J^(-2/3) C, as

- S = S_vol + S_iso, S_vol = J p C^-1 (p = U'(J)), S_iso = J^(-2/3) DEV(S_bar),
  DEV(X) = X - 1/3 (X : C) C^-1, S_bar = 2 (psi1 + I1b psi2) I - 2 psi2 C_bar;
- CC = CC_vol + CC_iso, CC_vol = J p~ C^-1 (x) C^-1 - 2 J p C^-1 (.) C^-1 (p~ = p + J dp/dJ),
  CC_iso = P : (J^(-4/3) CC_bar) : P^T + 2/3 Tr(J^(-2/3) S_bar) P~
  - 2/3 (C^-1 (x) S_iso + S_iso (x) C^-1), P = II - 1/3 C^-1 (x) C,
  P~ = C^-1 (.) C^-1 - 1/3 C^-1 (x) C^-1, Tr(X) = X : C, CC_bar = 4 d2Psi/dC_bar2;
- the element from P = F S and A_iJkL = delta_ik S_JL + F_iI CC_IJKL F_kK: f_a = -V0 P D_a,
  K_ab = V0 D_a A D_b.

A hand-written engine gets one of these pieces wrong. Here the pieces are built per cell from
the material's declared energy (``energy`` of its declaration, evaluated on hyper-dual numbers
in I1b, I2b and J: psi1, psi2, psi11, psi12, psi22, U', U''), for materials whose formula is
written in I1b, I2b and J alone and which declare a volumetric part; they are used only when
they add up to the oracle's force and stiffness to round-off. Ogden's one-term law, Psi =
c (tr C_bar^q - 3), is split the same way, its fictitious tangent the derivative of a matrix
power (:class:`PowerSumLaw`), with the pieces a spectral (Bonet and Wood) engine writes in
d tau_a / d ln lambda_b: its deviator's single and double traces and, where C's eigenvalues are
distinct, its principal entries. The engine-minus-oracle force and stiffness are then read as

- one piece, or two with the same factor, times a constant: -2 its sign flipped, -1 left out,
  -1/2 halved (a 2/3 written 1/3), +1 doubled. A piece of the stress (of S_bar, DEV's trace term,
  S_iso as a whole) changes everything the engine builds from it: the force, the geometric term
  delta_ik S_JL, the trace term (from S_bar) and the coupling term (from S_iso);
- a piece written another way, everything recomputed: DEV with tr(X) for X : C, the projection
  P transposed, J^(-2/3) applied to S_bar twice or not at all, J^(-4/3) of the fictitious
  tangent with another power.

A reading is named only when its prediction brings force and stiffness within the case's
tolerance; several that explain but predict differently are shown as ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from common.hyperdual import HD, exp, ln
from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.energy_terms import declaration
from conformance.diagnosis.findings import Finding, ambiguous
from conformance.diagnosis.mjed_parts import (
    Candidate,
    Pattern,
    explaining,
    mjed_parts,
    part_finding,
    residual,
    sparse_entries,
    with_equals,
)
from conformance.diagnosis.mjed_parts import candidates as mjed_candidates
from conformance.judge.compare import Scales, Tolerances

__all__ = [
    "Law",
    "Variant",
    "SplitParts",
    "decoupled_law",
    "split_parts",
    "split_part_findings",
    "split_part_reading",
]

#: Pieces that sum to the oracle to more than this (relative) are not used.
_ROUNDOFF = 1e-9
#: Larger meshes are not split (a few (m, 3, 3, 3, 3) tensors are held at once).
MAX_CELLS = 20000

_I = np.eye(3)
_II = 0.5 * (np.einsum("ik,jl->ijkl", _I, _I) + np.einsum("il,jk->ijkl", _I, _I))


# ------------------------------------------------------------------ the declared energy's law
class _Invariants:
    """The formula namespace with I1b, I2b, J (and ln J) only: a formula reading anything else
    (I1, C, E, a frame, eigenvalues) raises AttributeError, and is not split here.
    """

    __slots__ = ("I1b", "I2b", "J", "lnJ")
    exp = staticmethod(exp)
    ln = staticmethod(ln)

    def __init__(self, I1b, I2b, J):
        self.I1b, self.I2b, self.J, self.lnJ = I1b, I2b, J, ln(J)


@dataclass(frozen=True)
class Law:
    """Per cell (m,): the isochoric energy's derivatives by I1b and I2b and U'(J), U''(J)."""

    psi1: np.ndarray
    psi2: np.ndarray
    psi11: np.ndarray
    psi12: np.ndarray
    psi22: np.ndarray
    dU: np.ndarray
    d2U: np.ndarray

    def fictitious(self, Cb: np.ndarray) -> Tuple[Dict[str, np.ndarray], Dict[str, np.ndarray]]:
        """The parts of S_bar (2 psi1 I, 2 I1b psi2 I, -2 psi2 C_bar) (m, 3, 3) and of CC_bar
        by psi11, psi12, psi22 and psi2 (m, 3, 3, 3, 3), at C_bar (m, 3, 3).
        """
        m = len(Cb)
        I1b = np.trace(Cb, axis1=1, axis2=2)
        Id = np.broadcast_to(_I, (m, 3, 3))
        X = {
            "psi1": 2.0 * _col(self.psi1) * Id,
            "I1b-psi2": 2.0 * _col(I1b * self.psi2) * Id,
            "Cb-psi2": -2.0 * _col(self.psi2) * Cb,
        }
        G2 = _col(I1b) * Id - Cb  # dI2b/dC_bar
        II = np.broadcast_to(_II, (m, 3, 3, 3, 3))
        CCbar = {  # 4 d2Psi/dC_bar2 by the derivative of Psi it carries (Holzapfel 6.193)
            "psi11": 4.0 * _col4(self.psi11) * _outer(Id, Id),
            "psi12": 4.0 * _col4(self.psi12) * (_outer(Id, G2) + _outer(G2, Id)),
            "psi22": 4.0 * _col4(self.psi22) * _outer(G2, G2),
            "psi2": 4.0 * _col4(self.psi2) * (_outer(Id, Id) - II),
        }
        return X, CCbar


#: Eigenvalues of C closer than this (relative) are taken as equal: the principal frame in
#: their plane is then any, and the parts that depend on it are not formed.
_EQUAL = 1e-8


def _power_quotient(x: np.ndarray, p: float) -> np.ndarray:
    """(m, 3, 3) (x_a^p - x_b^p) / (x_a - x_b), its limit p x_a^(p-1) on the diagonal and for
    equal x, written through expm1 / log1p of the ratio so that near-equal x keep their digits.
    """
    xa, xb = x[:, :, None], x[:, None, :]
    d = (xa - xb) / xb
    tiny = np.abs(d) < 1e-12
    safe = np.where(tiny, 1.0, d)
    ratio = np.where(tiny, p, np.expm1(p * np.log1p(safe)) / safe)
    return xb ** (p - 1.0) * ratio


@dataclass(frozen=True)
class PowerSumLaw:
    """An isochoric energy Psi = c (tr C_bar^q - 3) (Ogden's one-term law, q = alpha / 2) and
    U'(J), U''(J) per cell (m,). Its fictitious tangent is a matrix function's derivative:
    in the eigenbasis N_a of C_bar, 4 c q f'(x_a) on the principal entries and the divided
    differences 4 c q (f(x_a) - f(x_b)) / (x_a - x_b) on the pairs (a != b), f = x^(q-1).
    """

    c: float
    q: float
    dU: np.ndarray
    d2U: np.ndarray

    def fictitious(self, Cb: np.ndarray) -> Tuple[Dict[str, np.ndarray], Dict[str, np.ndarray]]:
        """({"power": S_bar = 2 c q C_bar^(q-1)}, the parts of CC_bar): "principal" and
        "rotation" (the divided differences that turn the principal directions) where every
        cell's eigenvalues are distinct; else their sum alone, as "spectral".
        """
        x, N = np.linalg.eigh(Cb)
        k = 2.0 * self.c * self.q
        Sbar = np.einsum("mia,ma,mja->mij", N, k * x ** (self.q - 1.0), N)
        theta = 2.0 * k * _power_quotient(x, self.q - 1.0)
        eye = np.eye(3)
        principal = np.einsum("mab,mia,mja,mka,mla->mijkl", theta * eye, N, N, N, N)
        pairs = theta * (1.0 - eye)
        rotation = 0.5 * (
            np.einsum("mab,mia,mjb,mka,mlb->mijkl", pairs, N, N, N, N)
            + np.einsum("mab,mia,mjb,mkb,mla->mijkl", pairs, N, N, N, N)
        )
        if not distinct_eigenvalues(x):
            return {"power": Sbar}, {"spectral": principal + rotation}
        return {"power": Sbar}, {"principal": principal, "rotation": rotation}


def distinct_eigenvalues(x: np.ndarray) -> bool:
    """True when every cell's three eigenvalues (m, 3), sorted, are apart (:data:`_EQUAL`)."""
    return bool(np.all(np.diff(x, axis=1) > _EQUAL * np.abs(x).max(axis=1)[:, None]))


def _seeded(energy, p, I1b, I2b, J, seeds: Tuple[str, str]) -> Tuple[np.ndarray, np.ndarray]:
    """(dW/dx, d2W/dx dy) of the formula at (I1b, I2b, J), x and y the seeded names."""
    args = {"I1b": I1b, "I2b": I2b, "J": J}
    one = np.ones_like(J)
    x, y = seeds
    if x == y:
        args[x] = HD(args[x], one, one, 0.0)
    else:
        args[x] = HD(args[x], one, 0.0, 0.0)
        args[y] = HD(args[y], 0.0, one, 0.0)
    W = energy(p, _Invariants(args["I1b"], args["I2b"], args["J"]))
    m = len(J)
    if not isinstance(W, HD):
        return np.zeros(m), np.zeros(m)
    first = W.b if x == y else np.zeros(m)
    return np.broadcast_to(first, (m,)) + 0.0, np.broadcast_to(W.d, (m,)) + 0.0


def power_sum_law(model: Any, J: np.ndarray) -> Optional[PowerSumLaw]:
    """Ogden's law as :class:`PowerSumLaw` at per-cell J (m,), U from its declared volumetric
    energy; None for another model.
    """
    from mjed.materials.ogden import Ogden

    declared = declaration(model)
    if not isinstance(model, Ogden) or declared is None or declared.volumetric is None:
        return None
    alpha = float(model.alpha)
    one = np.ones_like(J)
    dU, d2U = _seeded(
        declared.volumetric, lambda n: float(getattr(model, n)), one, one, J, ("J", "J")
    )
    return PowerSumLaw(float(model.mu) / alpha**2, 0.5 * alpha, dU, d2U)


def decoupled_law(model: Any, I1b: np.ndarray, I2b: np.ndarray, J: np.ndarray) -> Optional[Law]:
    """The declared energy's psi1, psi2, psi11, psi12, psi22, U', U'' at per-cell (m,) I1b, I2b,
    J; None when the model has no declared formula in I1b, I2b and J alone with a volumetric
    part (NeoHookean, St Venant-Kirchhoff, Ogden, Costa, a user energy).
    """
    declared = declaration(model)
    if declared is None or declared.volumetric is None:
        return None

    def p(name):
        return float(getattr(model, name))

    try:
        psi1, psi11 = _seeded(declared.energy, p, I1b, I2b, J, ("I1b", "I1b"))
        psi2, psi22 = _seeded(declared.energy, p, I1b, I2b, J, ("I2b", "I2b"))
        _, psi12 = _seeded(declared.energy, p, I1b, I2b, J, ("I1b", "I2b"))
        dU, d2U = _seeded(declared.energy, p, I1b, I2b, J, ("J", "J"))
        _, mixed = _seeded(declared.energy, p, I1b, I2b, J, ("I1b", "J"))
    except (AttributeError, TypeError):
        return None
    scale = np.abs(psi11) + np.abs(psi1) + np.abs(d2U) + np.abs(dU)
    if np.any(np.abs(mixed) > 1e-10 * scale + 1e-300):
        return None  # Psi and U are not separate
    return Law(psi1, psi2, psi11, psi12, psi22, dU, d2U)


# ------------------------------------------------------------------ the split, per cell
def _outer(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def _odot(A, B):
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def _col(a):
    return a[:, None, None]


def _col4(a):
    return a[:, None, None, None, None]


def _project(P, T):
    """(P : T : P^T)_IJKL = P_IJAB T_ABCD P_KLCD, per cell, as 9x9 matrix products."""
    m = len(P)
    P9 = P.reshape(m, 9, 9)
    return (P9 @ T.reshape(m, 9, 9) @ P9.transpose(0, 2, 1)).reshape(m, 3, 3, 3, 3)


def _dot2(A, B):
    return np.einsum("mij,mij->m", A, B)


@dataclass(frozen=True)
class Variant:
    """How the split is written: right (the defaults) or one piece another way."""

    #: DEV(X) = X - 1/3 tr(X) C^-1 (for X : C); with trace_tr also Tr(X) of the trace term.
    dev_tr: bool = False
    trace_tr: bool = False
    #: P = II - 1/3 C (x) C^-1 (transposed) in P : CC~ : P^T.
    projection_transposed: bool = False
    #: S_bar multiplied by J^q (q = -2/3: J^(-2/3) applied twice; +2/3: not at all).
    sbar_power: float = 0.0
    #: the fictitious tangent's J^(-4/3) multiplied by J^q.
    cbar_power: float = 0.0


@dataclass(frozen=True)
class _Cells:
    """Per cell: V0 (m,), D (m, 4, 3), F, C, C^-1 (m, 3, 3), J (m,) and the law."""

    V0: np.ndarray
    D: np.ndarray
    F: np.ndarray
    C: np.ndarray
    Ci: np.ndarray
    J: np.ndarray
    law: Union[Law, PowerSumLaw]


#: A piece per cell: (S in the force (m, 3, 3) or None, S in the geometric term or None,
#: material tangent (m, 3, 3, 3, 3) or None).
_Piece = Tuple[Optional[np.ndarray], Optional[np.ndarray], Optional[np.ndarray]]


def _pieces(c: _Cells, v: Variant) -> Tuple[Dict[str, _Piece], Dict[str, _Piece]]:
    """(the partition: pieces that add up to the engine's S and CC; the stress pieces carried
    through everything built from them), written as ``v`` says.
    """
    law, C, Ci, J = c.law, c.C, c.Ci, c.J
    m = len(J)
    Jm23 = J ** (-2.0 / 3.0)
    Cb = _col(Jm23) * C
    X, CCbar = law.fictitious(Cb)
    X = {k: _col(J**v.sbar_power) * a for k, a in X.items()}
    Sbar = sum(X.values())

    def colon_C(A, tr):
        return np.trace(A, axis1=1, axis2=2) if tr else _dot2(A, C)

    Ptilde_odot, Ptilde_outer = _odot(Ci, Ci), -_outer(Ci, Ci) / 3.0

    def trace_term(A):  # 2/3 Tr(J^(-2/3) A) P~, as (odot part, outer part)
        t = 2.0 / 3.0 * Jm23 * colon_C(A, v.trace_tr)
        return _col4(t) * Ptilde_odot, _col4(t) * Ptilde_outer

    def coupling(S):
        return -2.0 / 3.0 * (_outer(Ci, S) + _outer(S, Ci))

    def dev_term(A):  # J^(-2/3) (-1/3 (A : C) C^-1)
        return _col(-Jm23 * colon_C(A, v.dev_tr) / 3.0) * Ci

    S_iso = _col(Jm23) * Sbar + dev_term(Sbar)
    pJ = J * law.dU
    Id4 = np.broadcast_to(_II, (m, 3, 3, 3, 3))
    proj = Id4 - (_outer(C, Ci) if v.projection_transposed else _outer(Ci, C)) / 3.0
    Jm43 = _col4(J ** (-4.0 / 3.0 + v.cbar_power))
    CCt = Jm43 * sum(CCbar.values())
    t_odot, t_outer = trace_term(Sbar)
    S_vol = _col(pJ) * Ci
    part: Dict[str, _Piece] = {
        "S_vol": (S_vol, S_vol, None),
        "S_iso": (S_iso, S_iso, None),
        "vol-p": (None, None, _col4(pJ) * _outer(Ci, Ci)),
        "vol-dp": (None, None, _col4(J * J * law.d2U) * _outer(Ci, Ci)),
        "vol-odot": (None, None, -2.0 * _col4(pJ) * _odot(Ci, Ci)),
        "iso-proj": (None, None, _project(proj, CCt)),
        "trace-odot": (None, None, t_odot),
        "trace-outer": (None, None, t_outer),
        "coupling": (None, None, coupling(S_iso)),
    }
    carried: Dict[str, _Piece] = {}
    for k, A in X.items():
        dS = _col(Jm23) * A + dev_term(A)
        a, b = trace_term(A)
        carried["Sbar-" + k] = (dS, dS, a + b + coupling(dS))
    dS = dev_term(Sbar)
    carried["dev"] = (dS, dS, coupling(dS))
    for k, T in CCbar.items():
        carried["CCbar-" + k] = (None, None, _project(proj, Jm43 * T))
    # P : CC~ : P^T written out (P = II - 1/3 C^-1 (x) C): CC~, its single contractions
    # -1/3 (C^-1 (x) (C : CC~) + (CC~ : C) (x) C^-1), and the double one 1/9 (C : CC~ : C)
    # C^-1 (x) C^-1; engines that expand it (spatially, c_bar's traces) drop or slip one
    left = np.einsum("mij,mijkl->mkl", C, CCt)  # C : CC~
    right = np.einsum("mijkl,mkl->mij", CCt, C)  # CC~ : C
    single = -(_outer(Ci, left) + _outer(right, Ci)) / 3.0
    double = _col4(np.einsum("mij,mij->m", left, C) / 9.0) * _outer(Ci, Ci)
    carried["proj-single"] = (None, None, single)
    carried["proj-double"] = (None, None, double)
    if isinstance(law, PowerSumLaw):
        carried.update(_spectral_pieces(law, C, Ci, J))
    return part, carried


def _spectral_pieces(law: PowerSumLaw, C, Ci, J) -> Dict[str, _Piece]:
    """The isochoric tangent of a power-sum law as a spectral engine writes it (Bonet and Wood:
    the spatial Kirchhoff tangent sum_ab d tau_a / d ln lambda_b n_a n_a n_b n_b - 2 sum_a
    tau_a n_a^4 + the shear terms), its pieces pulled back to the material frame
    (n_a n_a n_b n_b -> N_a N_a N_b N_b / (x_a x_b), I -> C^-1). With t_a = lambda_bar_a^alpha
    and mu = c alpha^2, the deviatoric tau_a = mu / alpha (t_a - sum t / 3) and
    d tau_a / d ln lambda_b = mu (t_a delta_ab - (t_a + t_b) / 3 + sum t / 9): the last two,
    the deviator's single and double traces, are tensors of C alone (in every cell); the first
    depends on the principal frame and is formed only where C's eigenvalues are distinct (the
    term -2 tau_a n_a^4, which needs the engine's frame where two coincide, is read by
    :func:`conformance.diagnosis.spectral_tangent.stress_term_findings`).
    """
    x, N = np.linalg.eigh(C)
    t = (_col(J ** (-2.0 / 3.0))[:, :, 0] * x) ** law.q  # lambda_bar_a^alpha (m, 3)
    mu = 4.0 * law.c * law.q**2
    B = np.einsum("ma,mia,mja->mij", t / x, N, N)  # b_bar^(alpha/2) pulled back
    out: Dict[str, _Piece] = {
        "spectral-double": (None, None, _col4(mu * t.sum(axis=1) / 9.0) * _outer(Ci, Ci)),
        "spectral-single": (None, None, -mu / 3.0 * (_outer(B, Ci) + _outer(Ci, B))),
    }
    if distinct_eigenvalues(x):
        quad = np.einsum("mia,mja,mka,mla->maijkl", N, N, N, N)
        out["spectral-diagonal"] = (None, None, np.einsum("ma,maijkl->mijkl", mu * t / x**2, quad))
    return out


def _element(c: _Cells, piece: _Piece, pat: Pattern) -> Tuple[np.ndarray, np.ndarray]:
    """A piece pushed to the assembled force (3n,) as the oracle's (-dW/dx) and stiffness (p,):
    f_a = -V0 F S D_a, K_ab = V0 D_a (delta_ik S_JL + F_iI CC_IJKL F_kK) D_b (batched matrix
    products, the cell axis first).
    """
    Sf, Sg, CC = piece
    F, D = c.F, c.D
    m = len(c.J)
    fe = np.zeros((m, 4, 3)) if Sf is None else np.einsum("mik,mkl,mal->mai", F, Sf, D)
    A = np.zeros((m, 3, 3, 3, 3))  # A_iJkL
    if CC is not None:
        A1 = (F @ CC.reshape(m, 3, 27)).reshape(m, 3, 3, 3, 3)  # (i, J, K, L)
        A2 = A1.transpose(0, 1, 2, 4, 3).reshape(m, 27, 3) @ F.transpose(0, 2, 1)  # (i, J, L, k)
        A = A2.reshape(m, 3, 3, 3, 3).transpose(0, 1, 2, 4, 3)
    if Sg is not None:
        A = A + np.einsum("ik,mJL->miJkL", _I, Sg)
    DT = D.transpose(0, 2, 1)  # (m, 3, 4)
    B = np.ascontiguousarray(A).reshape(m, 27, 3) @ DT  # (i, J, k, b)
    B = B.reshape(m, 3, 3, 3, 4).transpose(0, 1, 3, 4, 2).reshape(m, 36, 3) @ DT  # (i, k, b, a)
    Ke = B.reshape(m, 3, 3, 4, 4).transpose(0, 4, 1, 3, 2)  # (a, i, b, k)
    return -pat.force(fe, c.V0), pat.stiffness(Ke, c.V0)


def _summed(pieces: Dict[str, _Piece]) -> _Piece:
    """The pieces added up: one piece."""

    def add(i):
        xs = [p[i] for p in pieces.values() if p[i] is not None]
        return np.sum(xs, axis=0) if xs else None

    return add(0), add(1), add(2)


@dataclass(frozen=True)
class SplitParts:
    """A case's assembled pieces (name -> force (3n,), stiffness (p,)): the partition (adding up
    to the oracle), the stress pieces carried through, and each variant's change (variant
    minus right); and the element pattern.
    """

    part: Dict[str, Tuple[np.ndarray, np.ndarray]]
    carried: Dict[str, Tuple[np.ndarray, np.ndarray]]
    variants: Tuple[Tuple[str, np.ndarray, np.ndarray], ...]
    pattern: Pattern


#: Variants -> words.
VARIANTS: Tuple[Tuple[Variant, str], ...] = (
    (
        Variant(dev_tr=True),
        "the deviator DEV(S_bar) written with the trace, S_bar - 1/3 tr(S_bar) C^-1, for the "
        "reference-configuration S_bar - 1/3 (S_bar : C) C^-1, in S_iso = J^(-2/3) DEV(S_bar) "
        "(the force, and the geometric and coupling terms built from it)",
    ),
    (
        Variant(dev_tr=True, trace_tr=True),
        "tr(X) written for X : C both in the deviator DEV(S_bar) (S_iso) and in the trace term's "
        "Tr(J^(-2/3) S_bar)",
    ),
    (
        Variant(projection_transposed=True),
        "the projection tensor of the isochoric tangent written transposed, "
        "P = II - 1/3 C (x) C^-1 for II - 1/3 C^-1 (x) C, in P : (J^(-4/3) CC_bar) : P^T",
    ),
    (
        Variant(sbar_power=-2.0 / 3.0),
        "J^(-2/3) applied twice to the fictitious stress (S_bar taken as 2 dPsi/dC = J^(-2/3) "
        "2 dPsi/dC_bar, then S_iso = J^(-2/3) DEV(S_bar)): the isochoric stress carries "
        "J^(-4/3), in the force and the tangent terms built from S_bar",
    ),
    (
        Variant(sbar_power=2.0 / 3.0),
        "J^(-2/3) left out of S_iso = J^(-2/3) DEV(S_bar) (and of the trace term's "
        "Tr(J^(-2/3) S_bar)), in the force and the tangent terms built from S_bar",
    ),
    (
        Variant(cbar_power=2.0 / 3.0),
        "the fictitious tangent scaled by J^(-2/3) for J^(-4/3) in P : (J^(-4/3) CC_bar) : P^T",
    ),
    (
        Variant(cbar_power=-2.0 / 3.0),
        "the fictitious tangent scaled by J^(-2) for J^(-4/3) in P : (J^(-4/3) CC_bar) : P^T "
        "(J^(-2/3) applied once more)",
    ),
)


def _cells(model: Any, points, cells, x) -> Optional[_Cells]:
    V0, D, F = cell_kinematics(points, cells, x)
    C = np.einsum("mki,mkj->mij", F, F)
    J = np.linalg.det(F)
    if np.any(J <= 0.0):
        return None
    Cb = _col(J ** (-2.0 / 3.0)) * C
    I1b = np.trace(Cb, axis1=1, axis2=2)
    I2b = 0.5 * (I1b**2 - np.einsum("mij,mji->m", Cb, Cb))
    law = decoupled_law(model, I1b, I2b, J) or power_sum_law(model, J)
    if law is None:
        return None
    return _Cells(V0, D, F, C, np.linalg.inv(C), J, law)


def split_parts(
    model: Any, points: np.ndarray, cells: np.ndarray, x: np.ndarray, f_o: np.ndarray, K_o: Any
) -> Optional[SplitParts]:
    """The assembled pieces of the split at positions x (n, 3), or None when the model is not a
    decoupled invariant law (see :func:`decoupled_law`), or its pieces do not add up, to
    round-off, to the oracle's force f_o (n, 3) and stiffness K_o: then nothing is read.
    """
    if cells.shape[0] > MAX_CELLS:
        return None
    with np.errstate(all="ignore"):
        c = _cells(model, points, cells, x)
        if c is None:
            return None
        pat = Pattern.of(cells, points.shape[0])
        part_c, carried_c = _pieces(c, Variant())
        part = {k: _element(c, a, pat) for k, a in part_c.items()}
        carried = {k: _element(c, a, pat) for k, a in carried_c.items()}
    f_sum = np.sum([f for f, _ in part.values()], axis=0)
    K_sum = np.sum([K for _, K in part.values()], axis=0)
    if not (np.all(np.isfinite(f_sum)) and np.all(np.isfinite(K_sum))):
        return None
    K_on, K_off = sparse_entries(K_o, pat)
    nK = np.linalg.norm(K_on)
    if nK == 0 or K_off > (_ROUNDOFF * nK) ** 2 or np.linalg.norm(K_sum - K_on) > _ROUNDOFF * nK:
        return None
    f_ref = np.asarray(f_o, dtype=np.float64).ravel()
    # at rest S_vol's and S_iso's forces vanish: round-off is measured against the largest
    nf = max(np.linalg.norm(f_ref), max(np.linalg.norm(f) for f, _ in part.values()))
    if np.linalg.norm(f_sum - f_ref) > _ROUNDOFF * max(nf, 1e-300):
        return None
    variants = []
    with np.errstate(all="ignore"):
        for v, words in VARIANTS:
            f, K = _element(c, _summed(_pieces(c, v)[0]), pat)
            if np.all(np.isfinite(f)) and np.all(np.isfinite(K)):
                variants.append((words, f - f_sum, K - K_sum))
    return SplitParts(part, carried, tuple(variants), pat)


# ------------------------------------------------------------------ the readings
#: piece -> words an engineer finds in their code.
PIECES: Dict[str, str] = {
    "S_vol": "the volumetric stress S_vol = J p C^-1 (p = U'(J)), in the force P = F S and the "
    "geometric term delta_ik S_JL",
    "S_iso": "the isochoric stress S_iso = J^(-2/3) DEV(S_bar), in the force P = F S and the "
    "geometric term delta_ik S_JL (the coupling term right)",
    "vol-p": "the volumetric tangent's J p C^-1 (x) C^-1 (the p of p~ = p + J dp/dJ)",
    "vol-dp": "the volumetric tangent's J^2 dp/dJ C^-1 (x) C^-1 (the J dp/dJ of p~ = p + J dp/dJ)",
    "vol-odot": "the volumetric tangent's -2 J p C^-1 (.) C^-1",
    "vol": "the volumetric tangent J p~ C^-1 (x) C^-1 - 2 J p C^-1 (.) C^-1",
    "iso-proj": "the isochoric tangent's projected fictitious tangent P : (J^(-4/3) CC_bar) : P^T",
    "trace": "the isochoric tangent's trace term 2/3 Tr(J^(-2/3) S_bar) P~",
    "trace-odot": "the C^-1 (.) C^-1 of the modified projection P~ in the isochoric tangent's "
    "trace term 2/3 Tr(J^(-2/3) S_bar) P~",
    "trace-outer": "the -1/3 C^-1 (x) C^-1 of the modified projection P~ = C^-1 (.) C^-1 - 1/3 "
    "C^-1 (x) C^-1 in the isochoric tangent's trace term 2/3 Tr(J^(-2/3) S_bar) P~",
    "coupling": "the isochoric tangent's coupling term -2/3 (C^-1 (x) S_iso + S_iso (x) C^-1)",
    "CCbar-psi11": "the psi11 part 4 psi11 I (x) I of the fictitious tangent CC_bar (in the "
    "isochoric tangent's P : (J^(-4/3) CC_bar) : P^T; psi11 = d2W/dI1b2)",
    "CCbar-psi12": "the psi12 part 4 psi12 (I (x) G + G (x) I), G = I1b I - C_bar, of the "
    "fictitious tangent CC_bar (in the isochoric tangent's P : (J^(-4/3) CC_bar) : P^T; "
    "psi12 = d2W/dI1b dI2b)",
    "CCbar-psi22": "the psi22 part 4 psi22 G (x) G, G = I1b I - C_bar, of the fictitious tangent "
    "CC_bar (in the isochoric tangent's P : (J^(-4/3) CC_bar) : P^T; psi22 = d2W/dI2b2)",
    "CCbar-psi2": "the psi2 part 4 psi2 (I (x) I - II) of the fictitious tangent CC_bar (in the "
    "isochoric tangent's P : (J^(-4/3) CC_bar) : P^T; psi2 = dW/dI2b)",
    "Sbar-psi1": "the psi1 part 2 psi1 I of the fictitious stress S_bar",
    "Sbar-I1b-psi2": "the psi2 part 2 I1b psi2 I of the fictitious stress S_bar",
    "Sbar-Cb-psi2": "the psi2 part -2 psi2 C_bar of the fictitious stress S_bar",
    "Sbar-psi2": "the psi2 parts 2 psi2 (I1b I - C_bar) of the fictitious stress S_bar",
    "dev": "the deviator's -1/3 (S_bar : C) C^-1 in S_iso = J^(-2/3) DEV(S_bar)",
    "proj-single": "the single contractions -1/3 (C^-1 (x) (C : CC~) + (CC~ : C) (x) C^-1) of "
    "the projection P : CC~ : P^T written out (CC~ = J^(-4/3) CC_bar; spatially the "
    "-1/3 (I (x) (c_bar : I) + (I : c_bar) (x) I) of P : c_bar : P)",
    "proj-double": "the double contraction 1/9 (C : CC~ : C) C^-1 (x) C^-1 of the projection "
    "P : CC~ : P^T written out (CC~ = J^(-4/3) CC_bar; spatially the 1/9 (I : c_bar : I) "
    "I (x) I of P : c_bar : P)",
    "S_iso-all": "the isochoric stress S_iso = J^(-2/3) DEV(S_bar)",
    "Sbar-power": "the fictitious stress S_bar = 2 c q C_bar^(q-1) of the power sum "
    "c tr C_bar^q (Ogden, q = alpha/2)",
    "CCbar-principal": "the principal entries 4 c q f'(x_a) N_a^4 of the fictitious tangent "
    "CC_bar of Ogden's power sum (f = x^(q-1), x_a the eigenvalues of C_bar; spatially the "
    "delta_ab part of d tau_a / d ln lambda_b), in P : (J^(-4/3) CC_bar) : P^T",
    "CCbar-rotation": "the divided-difference (shear, a != b) terms of the fictitious tangent "
    "CC_bar of Ogden's power sum, which turn the principal directions, in "
    "P : (J^(-4/3) CC_bar) : P^T",
    "CCbar-spectral": "the fictitious tangent CC_bar of Ogden's power sum (the derivative of "
    "2 c q C_bar^(q-1)), in P : (J^(-4/3) CC_bar) : P^T",
    "spectral-double": "the mean term + mu/9 sum_c lambda_bar_c^alpha of Ogden's "
    "d tau_a / d ln lambda_b (from the derivative of the deviator's mean; spatially "
    "mu/(9J) sum_c lambda_bar_c^alpha I (x) I, the double trace 1/9 (1 . c_hat . 1) of the "
    "deviatoric projection in the principal frame)",
    "spectral-single": "the terms -mu/3 (lambda_bar_a^alpha + lambda_bar_b^alpha) of Ogden's "
    "d tau_a / d ln lambda_b (the deviatoric projection's single traces; spatially "
    "-mu/(3J) (b_bar^(alpha/2) (x) I + I (x) b_bar^(alpha/2)))",
    "spectral-diagonal": "the term mu lambda_bar_a^alpha delta_ab of Ogden's "
    "d tau_a / d ln lambda_b (the principal entries of the spectral tangent)",
}

#: Stress pieces carried through: where the engine uses them, in words.
_CARRIED = (
    " (in S_iso and all built from it: the force, the geometric term, the trace term and the "
    "coupling term)"
)
_CARRIED_DEV = " (in the force and the geometric and coupling terms built from S_iso)"

#: factor -> words, for one piece with a constant factor.
FACTORS: Dict[float, str] = {
    -2.0: "with its sign flipped",
    -1.0: "left out",
    -0.5: "halved",
    1.0: "doubled",
}

#: Pieces with a 2/3: their half is the 2/3 written 1/3.
_TWO_THIRDS = ("trace", "trace-odot", "trace-outer", "coupling")


def _words(name: str, k: float) -> str:
    """One piece with factor k in words."""
    if name == "vol-dp" and k == -1.0:
        return (
            "p~ written p, without J dp/dJ (p~ = p + J dp/dJ), in the volumetric tangent "
            "J p~ C^-1 (x) C^-1"
        )
    if name == "trace-outer" and k == -2.0:
        return (
            "the modified projection P~ written C^-1 (.) C^-1 + 1/3 C^-1 (x) C^-1 (the sign of "
            "its -1/3 C^-1 (x) C^-1 flipped) in the isochoric tangent's trace term "
            "2/3 Tr(J^(-2/3) S_bar) P~"
        )
    if name in _TWO_THIRDS and k == -0.5:
        return f"{PIECES[name]} written with 1/3 for 2/3"
    tail = _CARRIED_DEV if name == "dev" else _CARRIED if name in _STRESS else ""
    return f"{PIECES[name]} {FACTORS[k]}{tail}"


_STRESS = ("Sbar-psi1", "Sbar-I1b-psi2", "Sbar-Cb-psi2", "Sbar-psi2", "Sbar-power", "S_iso-all")


def _named(parts: SplitParts) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """Every piece read with a factor: the partition's, the carried ones, and their sums."""
    P, Cr = parts.part, parts.carried

    def add(*names, source):
        # a law without some of the pieces (Ogden's S_bar has no psi2 parts) adds what it has
        names = [n for n in names if n in source]
        return (
            np.sum([source[n][0] for n in names], axis=0),
            np.sum([source[n][1] for n in names], axis=0),
        )

    # the fictitious tangent's parts first: for a Psi of I1b alone its psi11 part is all of
    # P : (J^(-4/3) CC_bar) : P^T, and the more specific words are kept
    out = {k: a for k, a in Cr.items() if k.startswith("CCbar-")}
    out.update(P)
    out["vol"] = add("vol-p", "vol-dp", "vol-odot", source=P)
    out["trace"] = add("trace-odot", "trace-outer", source=P)
    out.update(Cr)
    if "Sbar-I1b-psi2" in Cr:
        out["Sbar-psi2"] = add("Sbar-I1b-psi2", "Sbar-Cb-psi2", source=Cr)
    out["S_iso-all"] = add(
        "Sbar-psi1", "Sbar-I1b-psi2", "Sbar-Cb-psi2", "Sbar-power", "dev", source=Cr
    )
    return {k: v for k, v in out.items() if np.any(v[0]) or np.any(v[1])}


#: The pieces paired (two wrong by the same factor): the partition's tangent pieces and the
#: carried stress pieces.
_PAIRED = (
    "S_vol",
    "vol-p",
    "vol-dp",
    "vol-odot",
    "iso-proj",
    "trace",
    "coupling",
    "trace-odot",
    "trace-outer",
    "Sbar-psi1",
    "Sbar-I1b-psi2",
    "Sbar-Cb-psi2",
    "Sbar-power",
    "dev",
)


def candidates(parts: SplitParts) -> List[Candidate]:
    """Every reading's predicted engine-minus-oracle, the most specific first: one piece with a
    factor, a piece written another way, two pieces with the same factor.
    """
    named = _named(parts)
    out = []
    for name, (df, dK) in named.items():
        for k in FACTORS:
            out.append(
                Candidate(
                    "split-part",
                    f"isochoric/volumetric split: {_words(name, k)}",
                    k * df,
                    k * dK,
                    {"piece": name, "factor": k},
                )
            )
    for words, df, dK in parts.variants:
        out.append(Candidate("split-variant", f"isochoric/volumetric split: {words}", df, dK, {}))
    paired = [n for n in _PAIRED if n in named]
    for i, a in enumerate(paired):
        for b in paired[i + 1 :]:
            for k in FACTORS:
                out.append(
                    Candidate(
                        "split-part",
                        f"isochoric/volumetric split: {_words(a, k)}; and {_words(b, k)}",
                        k * (named[a][0] + named[b][0]),
                        k * (named[a][1] + named[b][1]),
                        {"piece": f"{a}+{b}", "factor": k},
                    )
                )
    return out


def split_part_findings(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    K: Any,
    f_o: np.ndarray,
    K_o: Any,
    s: Scales,
    tol: Tolerances,
) -> Optional[List[Finding]]:
    """The readings whose prediction, added to the oracle's force f_o (n, 3) and stiffness K_o,
    brings the engine's f, K within ``tol`` (ambiguous when several predict differently); None
    when the model's pieces cannot be built or do not add up to the oracle.
    """
    parts = split_parts(model, points, cells, x, f_o, K_o)
    if parts is None:
        return None
    pat = parts.pattern
    f_o = np.asarray(f_o, dtype=np.float64)
    r, w, off = residual(pat, f, K, f_o, K_o, s)
    own = candidates(parts)
    kept = explaining(own, r, w, off, 3 * pat.n, tol)
    same: Dict[int, List[str]] = {}
    if kept:
        # An MJED engine's slip can give the same numbers as a split piece (Ogden, alpha = 3:
        # its term J^(-1) sum lambda^(3/2) has the J-J block of the spectral mean term): such
        # a twin is said beside the piece, so that neither is named alone where both fit.
        others = mjed_parts(model, points, cells, x, f_o, K_o)
        if others is not None:
            more = list(mjed_candidates(others, r, w))
            kept = explaining(own + more, r, w, off, 3 * pat.n, tol, same)
            kept = [(c, d) for c, d in kept if c in own]
    source = (
        "this change of Holzapfel's decoupled S and CC (pieces from the declared energy, which "
        "add up to the oracle to round-off)"
    )
    return ambiguous(
        [with_equals(part_finding(c, d, f, K, f_o, K_o, pat, s, source), same, c) for c, d in kept]
    )


def split_part_reading(diag: Any, ci: Any, out: Any, ref: Any, s: Scales) -> Any:
    """``diag`` with the split reading named first when one explains the engine (before any
    partial finding, and before a volumetric statement the error also fits); unchanged
    otherwise.
    """
    case = (ci.points, ci.cells, ci.positions, out.force, out.stiffness, ref.force, ref.stiffness)
    found = split_part_findings(ci.model, *case, s, diag.tolerances)
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
