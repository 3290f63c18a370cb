"""The engine's error read as MJED's chain-rule parts of the declared energy's terms.

An MJED engine (Marchesseau et al. 2010) writes the energy as terms f(J) g(C) (grouped where
the law needs it into c phi(sum of terms)), the force per node a as the J part f' g dJ_a and the
C part f F S D_a (dJ_a = J F^-T D_a), and the stiffness as per-edge 3x3 blocks: the J-J block
f'' g dJ_a dJ_b^T, the two cross blocks f' dJ_a (F S D_b)^T and f' (F S D_a) dJ_b^T, the
antisymmetric block f' g (dJ_a dJ_b^T - dJ_b dJ_a^T) / J, the geometric block f (D_a . S D_b) Id,
the material blocks f F L(a, b) F^T of the declared tangent pairs (beta (A : H) A, gamma B H B
with its two halves, the spectral pairs), and for a group phi'(u) times its terms' blocks plus
phi''(u) du_a du_b^T. A hand-written engine gets one of these parts wrong while the rest is
right, which no energy explains (the force and the stiffness no longer derive from one energy).

The parts are built from mjed's declared terms (:meth:`mjed.materials.base.Material.
decomposition`), per cell with einsum, and used only when they add up to the oracle's force and
stiffness to round-off. The engine-minus-oracle force and stiffness are then read as a sparse
combination of parts, one mechanism per family of hand-derivation mistakes:

- one part (of one term, or the same part of every term) with a constant factor: -2 its sign
  flipped, -1 left out, -1/2 halved, +1 added twice;
- the cross blocks written as one transposed twice (dJ_a (F S D_b)^T for both halves);
- f'(J) of one term wrong by a per-cell factor k J^p (p a multiple of 1/3, k fitted): the J part
  of the force and every f'-block scaled together, f and f'' right;
- f''(J) of one term wrong by a fitted constant (the J-J block alone: a power rule slipped in a
  hand second derivative); f'(J) in its stiffness blocks alone (the cross and antisymmetric
  blocks, the force's f' right), or its geometric or material blocks alone, each with a fitted
  factor (typed apart from the force in the tangent's code);
- the paper's regularisation of the J-J block (section 2.3) kept in compressed cells.
- a grouped term's gradient part with a constant factor where the gradient is formed: the force
  and the group's rank-one block c phi''(u) du_a du_b^T built from it change together;
- dJ_a written J F^-1 D_a (the inverse not transposed) or without J: every part recomputed;
- where the force is wrong, f = J^q of one term (or of every term with a power of J) written
  with another term's power: every part recomputed (the energy's formula changed);
- where the force is wrong, the J part of one term's stress (or of every term's) with another
  tensor than C^-1 (:mod:`conformance.diagnosis.pressure_tensor`): the force alone.

A reading is named only when its prediction brings force and stiffness within the case's
tolerance; readings that predict the same output are one; several that explain but predict
differently are shown as ambiguous. The antisymmetric block of every term is
:mod:`conformance.diagnosis.j_hessian_block`'s reading (same code and words), read here from the
declared terms; that module still reads materials mjed cannot split.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, ambiguous
from conformance.diagnosis.fractions import written_number
from conformance.diagnosis.j_hessian_block import FACTORS as J_HESSIAN_WORDS
from conformance.diagnosis.j_hessian_block import j_hessian_reading
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = [
    "Part",
    "Parts",
    "Candidate",
    "mjed_parts",
    "candidates",
    "mjed_part_findings",
    "mjed_part_reading",
    "Pattern",
    "sparse_entries",
    "residual",
    "explaining",
    "part_finding",
    "with_equals",
]

#: Parts that sum to the oracle to more than this (relative) are not used.
_ROUNDOFF = 1e-9
#: Larger meshes are not split: the per-cell blocks of every part are held at once (about
#: 1.2 kB a cell a part).
MAX_CELLS = 20000
#: Two predictions closer than this (relative to the residual) are one reading.
_SAME = 1e-6

#: part kind -> words an engineer finds in their code.
KINDS: Dict[str, str] = {
    "force-J": "force: the J part f'(J) g dJ_i (dJ_i = J F^-T D_i)",
    "force-C": "force: the C part f(J) F S D_i",
    "JJ": "stiffness: the J-J block f''(J) g dJ_i dJ_j^T",
    "cross-a": "stiffness: the cross block f'(J) dJ_i (F S D_j)^T",
    "cross-b": "stiffness: the cross block f'(J) (F S D_i) dJ_j^T",
    "anti": "stiffness: the antisymmetric J-Hessian block f'(J) g d2J/dx_i dx_j = f'(J) g "
    "(dJ_i dJ_j^T - dJ_j dJ_i^T) / J",
    "geometric": "stiffness: the geometric block f(J) (D_i . S D_j) Id",
    "first": "stiffness: the material block 2 beta f(J) (F A D_i)(F A D_j)^T of beta (A : H) A",
    "second-outer": "stiffness: the material block's half gamma f(J) (F B D_j)(F B D_i)^T of "
    "gamma B H B (for an I2 or tr C^2 term written in F: the term F_il F_kj of the Hessian "
    "d2(tr C^2)/dF2, from the dF^T of d(F F^T F))",
    "second-scaled": "stiffness: the material block's half gamma f(J) (D_i . B D_j) F B F^T of "
    "gamma B H B",
    "spectral": "stiffness: the spectral material block f(J) F (theta P_n H P_l) F^T",
    "group": "stiffness: the group's rank-one block c phi''(u) du_i du_j^T",
}

#: The parts that carry f'(J): what a wrong f' of one term changes, force and stiffness.
_DF = ("force-J", "cross-a", "cross-b", "anti")

#: factor -> words, for one part with a constant factor.
FACTORS: Dict[float, str] = {
    -2.0: "with its sign flipped",
    -1.0: "left out",
    -0.5: "halved",
    1.0: "added twice",
}


@dataclass(frozen=True)
class Part:
    """One part of one term: its kind (a key of KINDS), the term's label, and its assembled
    force (3n,) and stiffness entries on the element pattern (p,).
    """

    kind: str
    term: str
    force: np.ndarray
    stiffness: np.ndarray


@dataclass(frozen=True)
class Parts:
    """A case's parts, its J per cell (m,), the element pattern (rows, cols, each (p,)) and the
    regularisation deltas per term (a Part of kind "JJ", the regularised minus the exact block).
    """

    parts: Tuple[Part, ...]
    regularised: Tuple[Part, ...]
    J: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    terms: Tuple[str, ...]
    #: per term (label, its f'-parts per cell V0-weighted: force (m, 4, 3), stiffness
    #: (m, 4, 3, 4, 3)), to weight per cell by J^p, and the element pattern.
    df_cells: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()
    pattern: Any = None
    #: label -> the exponent q of f = J^q (JPower terms), to write the engine's f'.
    powers: Tuple[Tuple[str, float], ...] = ()
    #: a term's gradient part wrong by k where the group's rank-one block is built from it:
    #: (label or "", kind, S1 (p,), S2 (p,)), the block changing by k S1 + k^2 S2 ("" = the part
    #: of every term).
    gradient_blocks: Tuple[Tuple[str, str, np.ndarray, np.ndarray], ...] = ()
    #: (words, force (3n,), stiffness (p,)): everything recomputed with dJ_a written wrongly,
    #: minus the parts.
    dj_variants: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()
    #: the same with f = J^q of a term given another term's power (the energy changed too).
    power_copies: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()
    #: per term (label, all its parts per cell V0-weighted: force (m, 4, 3), stiffness
    #: (m, 4, 3, 4, 3)), to weight the whole term per cell by J^p (a term's volume).
    term_cells: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()
    #: per term (label, its J-J block per cell V0-weighted: force zero (m, 4, 3), stiffness
    #: (m, 4, 3, 4, 3)), to weight its f''(J) per cell by J^p (an exponent slipped in f'').
    d2f_cells: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()
    #: per scalar derivative of a term or group (f', f'', phi', phi''): (what it is, what it is
    #: a difference of, the parts it enters weighted per cell by the next derivative over it and
    #: by the one after over it, each force (3n,) and stiffness (p,) concatenated): what a
    #: difference quotient adds per unit of h/2 and of h^2/6.
    differences: Tuple[Tuple[str, str, np.ndarray, np.ndarray], ...] = ()
    #: (words, engine minus right force (3n,), stiffness (p,)): a block of one term (or of
    #: every term) weighted per cell by another factor (:data:`WEIGHTED_BLOCKS`), where J varies.
    weighted: Tuple[Tuple[str, np.ndarray, np.ndarray], ...] = ()


@dataclass(frozen=True)
class Candidate:
    """A predicted engine-minus-oracle (force (3n,), stiffness (p,)) with its words."""

    code: str
    title: str
    force: np.ndarray
    stiffness: np.ndarray
    figures: Dict[str, Any]


def _power_words(p: float) -> str:
    """J^(p) with p as a small fraction."""
    q = Fraction(p).limit_denominator(6)
    return "J" if q == 1 else f"J^({q})"


#: g(C) classes of mjed without an invariant's name, in words.
_G_WORDS: Dict[str, str] = {
    "GreenLagrangeQuadratic": "(lam/2 (tr E)^2 + mu tr(E^2), St Venant-Kirchhoff)",
    "EigenPowerSum": "(Ogden's sum of eigenvalue powers)",
    "FibreQuadratic": "(Costa's Q in the fibre frame)",
}


def term_label(term: Any) -> str:
    """A term in words: f(J) and g(C), the isochoric invariant named where it is one."""
    from mjed.terms import I1Power, JLogJ, JPower, LinearI2, LogPolynomial, Unity

    f, g = term.f, term.g
    fw = {
        JPower: lambda: "" if f.p == 0 else _power_words(f.p) + " ",
        LogPolynomial: lambda: "a (ln J)^2 + b ln J ",
        JLogJ: lambda: "k (J ln J - J + 1) ",
    }.get(type(f), lambda: type(f).__name__ + " ")()
    iso = isinstance(f, JPower)
    if isinstance(g, I1Power):
        gw = "I1" if g.n == 1 else f"I1^{g.n}"
        if iso and abs(f.p + 2.0 * g.n / 3.0) < 1e-12:
            gw += f" (I1b{'' if g.n == 1 else f'^{g.n}'})"
    elif isinstance(g, LinearI2):
        gw = "I2 (I2b)" if iso and abs(f.p + 4.0 / 3.0) < 1e-12 else "I2"
    elif isinstance(g, Unity):
        return f"{fw}(volumetric)"
    else:
        gw = _G_WORDS.get(type(g).__name__, type(g).__name__)
    return f"{fw}{gw}"


def _outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(m, 4, 3, 4, 3) u_a (x) v_b of node vectors u, v (m, 4, 3)."""
    return np.einsum("mai,mbj->maibj", u, v)


def _per_cell(x: Any, m: int) -> np.ndarray:
    """A scalar or (m,) as (m,)."""
    return np.broadcast_to(np.asarray(x, dtype=np.float64), (m,))


def _per_cell_matrix(M: np.ndarray, m: int) -> np.ndarray:
    """A (3, 3) or (m, 3, 3) matrix as (m, 3, 3)."""
    return np.broadcast_to(np.asarray(M, dtype=np.float64), (m, 3, 3))


def _material(term: Any, kin: Any, F: np.ndarray, D: np.ndarray) -> Dict[str, np.ndarray]:
    """The material blocks F L(a, b) F^T of g's declared tangent pairs, (m, 4, 3, 4, 3) by kind
    (summed over the pairs of one kind), without f(J).
    """
    m = F.shape[0]
    out: Dict[str, np.ndarray] = {}
    coeffs = term.g.tangent_coefficients(kin)
    for pair, beta in zip(term.g.tangent, coeffs):
        if pair.kind == "spectral":
            theta = np.broadcast_to(beta, (m, 3, 3))
            V = kin.eig[1]  # [m, j, n] = (v_n)_j
            P = np.einsum("mjn,mkn->mnjk", V, V)  # eigenprojectors of C
            # dS/dC : H = sum theta_nl P_n H P_l, H_bj = D_b (F^T e_j)^T + (F^T e_j) D_b^T
            T = np.einsum("mnl,mnkp,mlqr->mkrpq", theta, P, P)
            FT = np.einsum("mik,mkrpq->mirpq", F, T)
            A = np.einsum("mirpq,mar->maipq", FT, D)
            blk = np.einsum("maipq,mbp,mjq->maibj", A, D, F)
            blk = blk + np.einsum("maipq,mjp,mbq->maibj", A, F, D)
            out["spectral"] = out.get("spectral", 0.0) + blk
            continue
        b = _per_cell(beta, m)[:, None, None, None, None]
        M = _per_cell_matrix(pair.matrix, m)
        FMD = np.einsum("mik,mkl,mal->mai", F, M, D)
        if pair.kind == "first":
            out["first"] = out.get("first", 0.0) + 2.0 * b * _outer(FMD, FMD)
        else:
            DMD = np.einsum("mak,mkl,mbl->mab", D, M, D)
            FMF = np.einsum("mik,mkl,mjl->mij", F, M, F)
            outer = np.einsum("mbi,maj->maibj", FMD, FMD)
            scaled = np.einsum("mab,mij->maibj", DMD, FMF)
            out["second-outer"] = out.get("second-outer", 0.0) + b * outer
            out["second-scaled"] = out.get("second-scaled", 0.0) + b * scaled
    return out


def _term_parts(
    term: Any, kin: Any, F: np.ndarray, D: np.ndarray, dJ: np.ndarray
) -> Tuple[Dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """One term's parts per cell without the group's factor and V0: force (m, 4, 3) and
    stiffness (m, 4, 3, 4, 3) by kind; its gradient du_a (m, 4, 3); its value (m,).
    """
    m = F.shape[0]
    J = kin.J
    f, f1, f2 = (_per_cell(v, m) for v in term.f(J))
    g = _per_cell(term.g.value(kin), m)
    S = term.g.stress(kin)
    S = np.zeros((m, 3, 3)) if S is None else _per_cell_matrix(S, m)
    FSD = np.einsum("mik,mkl,mal->mai", F, S, D)
    c = (slice(None), None, None, None, None)
    JJ = _outer(dJ, dJ)
    parts = {
        "force-J": (f1 * g)[:, None, None] * dJ,
        "force-C": f[:, None, None] * FSD,
        "JJ": (f2 * g)[c] * JJ,
        "cross-a": f1[c] * _outer(dJ, FSD),
        "cross-b": f1[c] * _outer(FSD, dJ),
        "anti": (f1 * g / J)[c] * (JJ - np.einsum("mbi,maj->maibj", dJ, dJ)),
        "geometric": f[c] * np.einsum("mak,mkl,mbl,ij->maibj", D, S, D, np.eye(3)),
    }
    for kind, blk in _material(term, kin, F, D).items():
        parts[kind] = f[c] * blk
    return parts, parts["force-J"] + parts["force-C"], f * g


def _regularised(term: Any, kin: Any, dJ: np.ndarray) -> np.ndarray:
    """(m, 4, 3, 4, 3) the paper's regularised J-J block minus the exact one (section 2.3):
    f'' g b [(dJ_a . dJ_b) Id - dJ_a dJ_b^T], b = clip(1 - J, 0, 1).
    """
    m = dJ.shape[0]
    J = kin.J
    _, _, f2 = (_per_cell(v, m) for v in term.f(J))
    w = f2 * _per_cell(term.g.value(kin), m) * np.clip(1.0 - J, 0.0, 1.0)
    dd = np.einsum("mak,mbk,ij->maibj", dJ, dJ, np.eye(3))
    return w[:, None, None, None, None] * (dd - _outer(dJ, dJ))


@dataclass(frozen=True)
class Pattern:
    """The element pattern: dof (m, 12), the unique (rows, cols) (p,) and each element entry's
    index among them (m * 144,), n nodes.
    """

    dof: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    index: np.ndarray
    n: int

    @staticmethod
    def of(cells: np.ndarray, n: int) -> "Pattern":
        m = cells.shape[0]
        dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
        key = np.repeat(dof, 12, axis=1).ravel() * (3 * n) + np.tile(dof, (1, 12)).ravel()
        uniq, index = np.unique(key, return_inverse=True)
        return Pattern(dof, uniq // (3 * n), uniq % (3 * n), index.ravel(), n)

    def force(self, fe: np.ndarray, V0: np.ndarray) -> np.ndarray:
        """(3n,) the element forces (m, 4, 3) times V0 (m,), summed."""
        w = (V0[:, None, None] * fe).ravel()
        return np.bincount(self.dof.ravel(), weights=w, minlength=3 * self.n)

    def stiffness(self, Ke: np.ndarray, V0: np.ndarray) -> np.ndarray:
        """(p,) the element matrices (m, 4, 3, 4, 3) times V0 (m,), summed on the pattern."""
        w = (V0[:, None, None, None, None] * Ke).ravel()
        return np.bincount(self.index, weights=w, minlength=len(self.rows))


def sparse_entries(K: Any, pat: Pattern) -> Tuple[np.ndarray, float]:
    """K's entries on the pattern (p,) and the squared norm of those off it."""
    K = sp.csr_matrix(K)
    on = np.asarray(K[pat.rows, pat.cols]).ravel()
    # K minus its pattern entries: those cancel exactly, what is left is off the pattern
    off = K - sp.csr_matrix((on, (pat.rows, pat.cols)), shape=K.shape)
    return on, float(np.sum(np.abs(off.data) ** 2))


def _group_words(group: Any) -> str:
    """' in c phi(u)' for a group with a function of its sum, '' for a plain one."""
    if group.plain:
        return ""
    return f" (in the group c {type(group.function).__name__.lower()}(u))"


def _dj_right(J: np.ndarray, Finv: np.ndarray, D: np.ndarray) -> np.ndarray:
    """(m, 4, 3) dJ_a = J F^-T D_a (paper, eq. 4)."""
    return J[:, None, None] * np.einsum("mji,maj->mai", Finv, D)


#: dJ_a written wrongly by hand -> (words, dJ (m, 4, 3) from J (m,), F^-1 (m, 3, 3), D).
DJ_VARIANTS = (
    (
        "J F^-1 D_i for J F^-T D_i (the inverse not transposed)",
        lambda J, Finv, D: J[:, None, None] * np.einsum("mij,maj->mai", Finv, D),
    ),
    (
        "F^-T D_i for J F^-T D_i (the factor J left out)",
        lambda J, Finv, D: _dj_right(J, Finv, D) / J[:, None, None],
    ),
)


@dataclass(frozen=True)
class _Group:
    """What a group with a function of its sum builds its rank-one block from: c phi''(u) (m,),
    du (m, 4, 3), and each of its terms' gradient parts (label, kind, (m, 4, 3)), without V0.
    """

    w2: np.ndarray
    du: np.ndarray
    pieces: Tuple[Tuple[str, str, np.ndarray], ...]


def _group_parts(
    group: Any, kin: Any, F: np.ndarray, D: np.ndarray, dJ: np.ndarray
) -> Tuple[list, list, Optional[_Group]]:
    """One group's [(parts by kind, label)] scaled by c phi'(u) (its rank-one block last), its
    regularisation deltas [(array, label)] and its _Group (None for a plain group).
    """
    m = len(kin.J)
    built = [_term_parts(term, kin, F, D, dJ) for term in group.terms]
    labels = [term_label(t) + _group_words(group) for t in group.terms]
    u = np.sum([value for _, _, value in built], axis=0)
    w1, w2 = group.coefficient, 0.0
    if not group.plain:
        _, d1, d2 = group.function(u)
        w1, w2 = group.coefficient * d1, group.coefficient * d2
    w1 = _per_cell(w1, m)[:, None, None, None, None]
    out = []
    for (parts, _, _), label in zip(built, labels):
        # a group's terms enter as c phi'(u) times their parts
        out.append(
            ({k: (w1[..., 0, 0] if k[:5] == "force" else w1) * a for k, a in parts.items()}, label)
        )
    reg = [(w1 * _regularised(t, kin, dJ), label) for t, label in zip(group.terms, labels)]
    if group.plain:
        return out, reg, None
    du = np.sum([grad for _, grad, _ in built], axis=0)
    w2 = _per_cell(w2, m)
    out.append(({"group": w2[:, None, None, None, None] * _outer(du, du)}, _rank_one_label(group)))
    pieces = tuple(
        (label, kind, parts[kind])
        for (parts, _, _), label in zip(built, labels)
        for kind in ("force-J", "force-C")
    )
    return out, reg, _Group(w2, du, pieces)


def _rank_one_label(group: Any) -> str:
    """The words c phi(terms) of a group with a function of its sum."""
    words = ", ".join(term_label(t) for t in group.terms)
    return f"c {type(group.function).__name__.lower()}({words})"


def _cell_parts(
    model: Any, points: np.ndarray, cells: np.ndarray, x: np.ndarray, dj=_dj_right
) -> Optional[tuple]:
    """[(kind, label, per-cell array)] of every term and group, the regularisation deltas
    [(array, label)], the _Groups, V0 (m,) and J (m,); None when the model has no MJED
    decomposition. dj: how dJ_a is formed (the paper's, or a variant written wrongly).
    """
    from mjed.kinematics import Kinematics

    try:
        groups = model.decomposition()
    except Exception:  # noqa: BLE001 - not an MJED material: nothing to split
        return None
    V0, D, F = cell_kinematics(points, cells, x)
    kin = Kinematics(F)
    dJ = dj(kin.J, np.linalg.inv(F), D)
    out, reg, grouped = [], [], []
    for group in groups:
        o, r, g = _group_parts(group, kin, F, D, dJ)
        out += o
        reg += r
        grouped += [] if g is None else [g]
    flat = [(kind, label, arr) for parts, label in out for kind, arr in parts.items()]
    return flat, reg, grouped, V0, kin.J


def mjed_parts(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    f_o: np.ndarray,
    K_o: Any,
) -> Optional[Parts]:
    """The assembled parts of every term of ``model`` at positions x (n, 3), or None when the
    model has no MJED decomposition or the parts do not add up, to round-off, to the oracle's
    force f_o (n, 3) and stiffness K_o (3n, 3n): then nothing is read from them.
    """
    if cells.shape[0] > MAX_CELLS:
        return None
    built = _cell_parts(model, points, cells, x)
    if built is None:
        return None
    flat, reg, grouped, V0, J = built
    pat = Pattern.of(cells, points.shape[0])
    parts = tuple(
        Part(kind, label, -pat.force(a, V0), np.zeros(0))  # the oracle's force is -dW/dx
        if kind.startswith("force")
        else Part(kind, label, np.zeros(3 * pat.n), pat.stiffness(a, V0))
        for kind, label, a in flat
    )
    parts = tuple(
        replace(p, stiffness=np.zeros(len(pat.rows))) if p.kind.startswith("force") else p
        for p in parts
    )
    f_sum = np.sum([p.force for p in parts], axis=0)
    K_sum = np.sum([p.stiffness for p in parts], axis=0)
    K_on, K_off = sparse_entries(K_o, pat)
    f_ref = np.asarray(f_o, dtype=np.float64).ravel()
    nf, nK = np.linalg.norm(f_ref), np.linalg.norm(K_on)
    if nK == 0 or K_off > (_ROUNDOFF * nK) ** 2:
        return None
    if np.linalg.norm(K_sum - K_on) > _ROUNDOFF * nK:
        return None
    # at rest the force parts cancel: round-off is measured against the largest of them
    nf = max(nf, max(np.linalg.norm(p.force) for p in parts))
    if np.linalg.norm(f_sum - f_ref) > _ROUNDOFF * max(nf, 1e-300):
        return None
    regularised = tuple(
        Part("JJ-regularised", label, np.zeros(3 * pat.n), pat.stiffness(a, V0)) for a, label in reg
    )
    terms = tuple(dict.fromkeys(p.term for p in parts))
    return Parts(
        parts,
        regularised,
        J,
        pat.rows,
        pat.cols,
        terms,
        _df_cells(terms, flat, V0),
        pat,
        _powers(model),
        _gradient_blocks(grouped, pat, V0),
        _dj_variants(model, _State(points, cells, x, pat, f_sum, K_sum)),
        term_cells=_df_cells(terms, flat, V0, kinds=None),
        d2f_cells=_df_cells(terms, flat, V0, kinds=("JJ",)),
        differences=_difference_slots(model, points, cells, x, flat, V0, pat),
        weighted=_weighted_blocks(model, flat, V0, J, pat),
    )


#: blocks an engine builds in one place, and per-cell factors one such place may carry by
#: mistake: (kinds, the block in words, {key: words}); keys: "1/J", "1/J^2", "J" (a factor J
#: of dJ_i = J F^-T D_i lost, or one too many), "f/f'" (the function for its first derivative),
#: "f'/f''" (the first derivative for the second).
WEIGHTED_BLOCKS: Tuple[Tuple[Tuple[str, ...], str, Dict[str, str]], ...] = (
    (
        ("anti",),
        "the antisymmetric J-Hessian block f'(J) g d2J",
        {
            "f/f'": "with f(J) where f'(J) belongs (f g d2J for f' g d2J)",
            "1/J": "divided by J (a factor J of d2J lost)",
            "J": "times J",
        },
    ),
    (
        ("cross-a", "cross-b"),
        "both cross blocks f'(J) (dJ_i (F S D_j)^T + (F S D_i) dJ_j^T)",
        {
            "1/J": "formed with F^-T D_i where dJ_i = J F^-T D_i belongs (the factor J lost there)",
            "J": "times J",
            "f/f'": "with f(J) where f'(J) belongs",
        },
    ),
    (
        ("JJ",),
        "the J-J block f''(J) g dJ_i dJ_j^T",
        {
            "1/J^2": "formed with F^-T D_i where dJ_i = J F^-T D_i belongs (J^2 lost there)",
            "1/J": "divided by J",
            "J": "times J",
            "f'/f''": "with f'(J) where f''(J) belongs",
        },
    ),
    (
        ("geometric",),
        "the geometric block f(J) (D_i . S D_j) Id",
        {"J": "times J (the deformed volume J V0)", "1/J": "divided by J"},
    ),
)


def _weighted_blocks(
    model: Any, flat: list, V0: np.ndarray, J: np.ndarray, pat: "Pattern"
) -> Tuple[Tuple[str, np.ndarray, np.ndarray], ...]:
    """Each block of :data:`WEIGHTED_BLOCKS`, of each term and of every term, weighted per cell
    by each of its factors: (words, engine minus right force (3n,), stiffness (p,)). Each is an
    exact prediction, nothing fitted, so it is tried on one J too (where the factor is one
    number: the case where J varies tells it from a constant).
    """
    m = len(J)
    ratios: Dict[str, Dict[str, np.ndarray]] = {}
    for group in model.decomposition():
        for t in group.terms:
            f, f1, f2 = (_per_cell(v, m) for v in t.f(J))
            ratios[term_label(t) + _group_words(group)] = {
                "1/J": 1.0 / J,
                "1/J^2": J**-2.0,
                "J": J,
                "f/f'": _next_over(f, f1),
                "f'/f''": _next_over(f1, f2),
            }
    out = []
    zero_f = np.zeros(3 * pat.n)
    for kinds, block, factors in WEIGHTED_BLOCKS:
        # each term's blocks of these kinds per cell, V0-weighted: the same for every factor
        blocks = {
            label: sum(
                (
                    V0[:, None, None, None, None] * a
                    for k, lab, a in flat
                    if lab == label and k in kinds
                ),
                0.0,
            )
            for label in ratios
        }
        for key, words in factors.items():
            each = []
            for label, r in ratios.items():
                Ke = blocks[label]
                if not np.any(Ke):
                    continue
                dK = pat.stiffness(np.broadcast_to(Ke, (m, 4, 3, 4, 3)), r[key] - 1.0)
                if np.any(dK):
                    each.append((label, dK))
                    out.append((f"MJED {block} of the term {label} {words}", zero_f, dK))
            if len(each) > 1:
                total = np.sum([dK for _, dK in each], axis=0)
                out.append((f"MJED {block} of every term {words}", zero_f, total))
    return tuple(out)


def _next_over(value: np.ndarray, this: np.ndarray) -> np.ndarray:
    """The ratio value / this per cell, 0 where ``this`` is 0 (a derivative that enters
    nothing).
    """
    this = np.asarray(this, dtype=float)
    safe = np.where(this == 0.0, 1.0, this)
    return np.where(this == 0.0, 0.0, np.asarray(value, dtype=float) / safe)


def _higher(second: Any, u: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The first and second derivatives of ``second`` (a function of u returning (m,)) by
    central differences, step 1e-3 of max(1, |u|): good to about 1e-7 and 1e-6 relative,
    enough for ratios of derivatives that size a truncation error.
    """
    h = 1e-3 * np.maximum(1.0, np.abs(u))
    up, mid, down = second(u + h), second(u), second(u - h)
    return (up - down) / (2.0 * h), (up - 2.0 * mid + down) / (h * h)


def _difference_slots(
    model: Any, points, cells, x, flat: list, V0: np.ndarray, pat: "Pattern"
) -> Tuple[Tuple[str, str, np.ndarray, np.ndarray], ...]:
    """Per term, f'(J) (its f'-parts) and f''(J) (its J-J block); per group with a function of
    its sum, phi'(u) (every part of its terms) and phi''(u) (its rank-one block): the parts
    weighted per cell by the next derivative over this one (a forward difference of the
    function below with step h adds h/2 of it), assembled (see Parts.differences).
    """
    from mjed.kinematics import Kinematics

    F = cell_kinematics(points, cells, x)[2]
    kin = Kinematics(F)
    J, m = kin.J, len(kin.J)
    out = []

    def weighted(fe, Ke, rho: np.ndarray) -> np.ndarray:
        force = pat.force(np.broadcast_to(fe, (m, 4, 3)), rho) if np.any(fe) else 0.0
        stiffness = pat.stiffness(np.broadcast_to(Ke, (m, 4, 3, 4, 3)), rho) if np.any(Ke) else 0.0
        return np.concatenate([np.zeros(3 * pat.n) + force, np.zeros(len(pat.rows)) + stiffness])

    def slot(what, of, labels: set, kinds: Optional[Tuple[str, ...]], d: Tuple[np.ndarray, ...]):
        """d: this derivative and the next two, per cell (m,) each."""
        mine = [
            (k, a)
            for k, label, a in flat
            if label in labels and (kinds is None and k != "group" or kinds and k in kinds)
        ]
        fe = sum((-V0[:, None, None] * a for k, a in mine if k.startswith("force")), 0.0)
        Ke = sum(
            (V0[:, None, None, None, None] * a for k, a in mine if not k.startswith("force")), 0.0
        )
        first = weighted(fe, Ke, _next_over(d[1], d[0]))
        if np.any(first):
            out.append((what, of, first, weighted(fe, Ke, _next_over(d[2], d[0]))))

    for group in model.decomposition():
        labels = {term_label(t) + _group_words(group) for t in group.terms}
        for t in group.terms:
            label = term_label(t) + _group_words(group)
            _, f1, f2 = (_per_cell(v, m) for v in t.f(J))
            f3, f4 = _higher(lambda j, t=t: _per_cell(t.f(j)[2], m), J)
            slot(f"f'(J) of the term {label}", "f(J)", {label}, _DF, (f1, f2, f3))
            slot(f"f''(J) of the term {label}", "f'(J)", {label}, ("JJ",), (f2, f3, f4))
        if group.plain:
            continue
        u = np.sum([_per_cell(t.f(J)[0] * t.g.value(kin), m) for t in group.terms], axis=0)
        _, d1, d2 = (_per_cell(v, m) for v in group.function(u))
        d3, d4 = _higher(lambda v: _per_cell(group.function(v)[2], m), u)
        name = _rank_one_label(group)
        slot(f"phi'(u) of {name}", "phi(u)", labels, None, (d1, d2, d3))
        slot(f"phi''(u) of {name}", "phi'(u)", {name}, ("group",), (d2, d3, d4))
    return tuple(out)


def _df_cells(
    terms: Tuple[str, ...], flat: list, V0: np.ndarray, kinds: Optional[Tuple[str, ...]] = _DF
) -> Tuple[Tuple[str, np.ndarray, np.ndarray], ...]:
    """Per term, its f'-parts (``kinds``; None: all its parts) per cell times V0: the force
    (m, 4, 3) as the oracle's (-dW/dx) and the blocks (m, 4, 3, 4, 3), for _power (or _volume)
    to weight per cell by J^p.
    """
    out = []
    for t in terms:
        mine = [(k, a) for k, label, a in flat if label == t and (kinds is None or k in kinds)]
        forces = [a for k, a in mine if k.startswith("force")]
        fe = sum((-V0[:, None, None] * a for a in forces), np.zeros((1, 4, 3)))
        Ke = sum(
            (V0[:, None, None, None, None] * a for k, a in mine if not k.startswith("force")),
            np.zeros((1, 4, 3, 4, 3)),
        )
        out.append((t, np.broadcast_to(fe, (len(V0), 4, 3)), Ke))
    return tuple(out)


def _gradient_blocks(
    grouped: List[_Group], pat: "Pattern", V0: np.ndarray
) -> Tuple[Tuple[str, str, np.ndarray, np.ndarray], ...]:
    """For each grouped term's gradient part a (and the part of every term, summed per group):
    S1 = c phi'' (a du^T + du a^T) and S2 = c phi'' a a^T, assembled (see Parts).
    """
    out = []
    every: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}
    for grp in grouped:
        w = grp.w2[:, None, None, None, None]
        sums: Dict[str, np.ndarray] = {}
        for label, kind, a in grp.pieces:
            sums[kind] = sums.get(kind, 0.0) + a
            S1 = pat.stiffness(w * (_outer(a, grp.du) + _outer(grp.du, a)), V0)
            out.append((label, kind, S1, pat.stiffness(w * _outer(a, a), V0)))
        for kind, a in sums.items():
            S1 = pat.stiffness(w * (_outer(a, grp.du) + _outer(grp.du, a)), V0)
            S2 = pat.stiffness(w * _outer(a, a), V0)
            prev = every.get(kind, (0.0, 0.0))
            every[kind] = (prev[0] + S1, prev[1] + S2)
    return tuple(out) + tuple(("", kind, S1, S2) for kind, (S1, S2) in every.items())


@dataclass(frozen=True)
class _State:
    """Where the parts are taken: rest points (n, 3), cells (m, 4), positions x (n, 3), the
    element pattern, and the right parts' summed force (3n,) and stiffness (p,).
    """

    points: np.ndarray
    cells: np.ndarray
    x: np.ndarray
    pat: "Pattern"
    f_sum: np.ndarray
    K_sum: np.ndarray

    def change(self, model: Any, dj=_dj_right) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """All parts of ``model`` with dJ_a from dj (summed per cell before assembling) minus
        the right ones: force (3n,), stiffness (p,); None where not finite.
        """
        pat = self.pat
        with np.errstate(all="ignore"):
            flat, _, _, V0, _ = _cell_parts(model, self.points, self.cells, self.x, dj)
            f = -pat.force(sum(a for k, _, a in flat if k[:5] == "force"), V0)
            K = pat.stiffness(sum(a for k, _, a in flat if k[:5] != "force"), V0)
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(K))):
            return None
        return f - self.f_sum, K - self.K_sum


def _dj_variants(model: Any, st: _State) -> Tuple[Tuple[str, np.ndarray, np.ndarray], ...]:
    """(words, force (3n,), stiffness (p,)) of every DJ_VARIANTS: all parts with that dJ_a,
    minus the right ones.
    """
    out = []
    for words, dj in DJ_VARIANTS:
        d = st.change(model, dj)
        if d is not None:
            out.append((words, *d))
    return tuple(out)


@dataclass(frozen=True)
class _Declared:
    """A stand-in material: the given term groups."""

    groups: Tuple[Any, ...]

    def decomposition(self) -> Tuple[Any, ...]:
        return self.groups


def _power_copies(model: Any, st: _State) -> Tuple[Tuple[str, np.ndarray, np.ndarray], ...]:
    """(words, force (3n,), stiffness (p,)): f = J^q of one term (or of every term with a power
    of J) written with the power q' of another term, the energy's formula changed, minus the
    right parts.
    """
    from mjed.terms import JPower

    groups = model.decomposition()
    where = [
        (i, j)
        for i, g in enumerate(groups)
        for j, t in enumerate(g.terms)
        if isinstance(t.f, JPower) and t.f.p != 0
    ]
    powers = sorted({groups[i].terms[j].f.p for i, j in where})
    sets = [([w], f"f(J) of the term {term_label(groups[w[0]].terms[w[1]])}") for w in where]
    sets += [(where, "f(J) of every term with a power of J")] if len(where) > 2 else []
    out = []
    for chosen, which in sets:
        for q in powers:
            if all(groups[i].terms[j].f.p == q for i, j in chosen):
                continue
            new = [list(g.terms) for g in groups]
            for i, j in chosen:
                new[i][j] = replace(new[i][j], f=JPower(q))
            variant = _Declared(tuple(replace(g, terms=tuple(t)) for g, t in zip(groups, new)))
            d = st.change(variant)
            if d is not None:
                out.append((f"{which} written {_power_words(q)} (another term's power of J)", *d))
    return tuple(out)


def _shift_copies(model: Any, st: _State) -> Tuple[Tuple[str, np.ndarray, np.ndarray], ...]:
    """(words, force (3n,), stiffness (p,)): the constant (shift) of a group's function phi
    written with a simple multiple of 1/p (p a parameter) lost or added, or as 0 or 1: the rest
    constant of a shifted argument (Gent's ln(1 + 3/Jm - I1b/Jm) written ln(1 - I1b/Jm)), the
    energy's formula changed, minus the right parts.
    """
    import dataclasses

    from conformance.diagnosis.fractions import written_number
    from conformance.diagnosis.parameters import scalar_parameters

    params = scalar_parameters(model)
    groups = model.decomposition()
    out = []
    for i, g in enumerate(groups):
        shift = getattr(g.function, "shift", None)
        if shift is None or not dataclasses.is_dataclass(g.function):
            continue
        tried = {float(shift)}
        options = []
        for p, v in params.items():
            if v:
                for k in (3.0, -3.0, 1.0, -1.0):
                    said = f"{written_number(abs(k))}/{p} {'lost' if k > 0 else 'added'}"
                    options.append((shift - k / v, said))
        for value, why in options + [(0.0, "written 0"), (1.0, "written 1")]:
            if any(abs(value - t) <= 1e-12 * max(1.0, abs(t)) for t in tried):
                continue
            tried.add(value)
            fn = dataclasses.replace(g.function, shift=value)
            new = list(groups)
            new[i] = replace(g, function=fn)
            d = st.change(_Declared(tuple(new)))
            if d is not None:
                name = type(g.function).__name__.lower()
                out.append(
                    (
                        f"the constant of the group c {name}(shift + u) written {value:.6g} where "
                        f"{shift:.6g} belongs ({why}: the rest constant of a shifted argument)",
                        *d,
                    )
                )
    return tuple(out)


def _powers(model: Any) -> Tuple[Tuple[str, float], ...]:
    """(label, q) of every term with f = J^q, q != 0."""
    from mjed.terms import JPower

    out = []
    for group in model.decomposition():
        for term in group.terms:
            if isinstance(term.f, JPower) and term.f.p != 0:
                out.append((term_label(term) + _group_words(group), float(term.f.p)))
    return tuple(out)


#: parts written together in an engine's code, tried as one with a constant factor:
#: name -> (kinds, words as KINDS has them).
KIND_GROUPS: Dict[str, Tuple[Tuple[str, ...], str]] = {
    "cross": (
        ("cross-a", "cross-b"),
        "stiffness: both product-rule cross blocks f'(J) (dJ_i (F S D_j)^T + (F S D_i) dJ_j^T)",
    ),
}


def _single(parts: Parts) -> List[Candidate]:
    """One part of one term, then the same part of every term, with each constant factor; the
    same for the parts of :data:`KIND_GROUPS`.
    """
    nonzero = [p for p in parts.parts if np.any(p.force) or np.any(p.stiffness)]
    pieces = [(p.kind, f"of the term {p.term}", (p,)) for p in nonzero]
    for kind in KINDS:
        same = tuple(p for p in nonzero if p.kind == kind)
        if len(same) > 1:
            pieces.append((kind, "of every term", same))
    for name, (kinds, _) in KIND_GROUPS.items():
        for term in parts.terms:
            mine = tuple(p for p in nonzero if p.term == term and p.kind in kinds)
            if len(mine) > 1:
                pieces.append((name, f"of the term {term}", mine))
        every = tuple(p for p in nonzero if p.kind in kinds)
        if len({p.term for p in every}) > 1:
            pieces.append((name, "of every term", every))
    n_anti = sum(p.kind == "anti" for p in nonzero)
    out = []
    for kind, which, ps in pieces:
        df = np.sum([p.force for p in ps], axis=0)
        dK = np.sum([p.stiffness for p in ps], axis=0)
        for k, words in FACTORS.items():
            said = KINDS[kind] if kind in KINDS else KIND_GROUPS[kind][1]
            code, title = "mjed-part", f"MJED {said} {which} {words}"
            if kind == "force-J" and k == -1.0 and which.startswith("of the term J^(-"):
                title += _ISOCHORIC_FACTOR_LOST
            if kind == "anti" and len(ps) == n_anti and k in J_HESSIAN_WORDS:
                # the J-Hessian block of the whole energy: j_hessian_block's reading
                code, title = "j-hessian-block", f"MJED {KINDS[kind]} {J_HESSIAN_WORDS[k]}"
            out.append(
                Candidate(code, title, k * df, k * dK, {"part": kind, "factor": k, "terms": which})
            )
    return out


#: The J part of a term J^p g(C) (p < 0, an isochoric factor) left out of the force, in the words
#: of engines that do not split terms so: the factor's derivative dropped from the chain rule.
_ISOCHORIC_FACTOR_LOST = (
    " (in an engine's own chain rule: the derivative of the isochoric factor J^p dropped, the "
    "isochoric stress no longer deviatoric; an invariant engine's -1/3 I1 C^-1 of the "
    "isochoric projection of dI1b/dC, or a principal-stretch engine's -1/3 J^(-1/3) "
    "lambda_i / lambda_j term of the deviatoric stretches' chain d lambda_bar_i / d lambda_j)"
)

#: A force part and the stiffness blocks that are its derivative: an engine whose stiffness is
#: the derivative of its force (a complex step, differences of the force routine) carries a
#: force part's factor into them.
_DERIVED = {
    "force-C": ("cross-b", "geometric", "first", "second-outer", "second-scaled", "spectral"),
    "force-J": ("JJ", "cross-a", "anti"),
}


def _derived(parts: Parts) -> List[Candidate]:
    """One force part of one term with a constant factor, in the force and in the stiffness
    blocks derived from it (:data:`_DERIVED`), as an engine differentiating its own force has
    them.
    """
    out = []
    for term in parts.terms:
        for kind, blocks in _DERIVED.items():
            ps = [p for p in parts.parts if p.term == term and (p.kind == kind or p.kind in blocks)]
            if not any(p.kind == kind and np.any(p.force) for p in ps):
                continue
            df = np.sum([p.force for p in ps], axis=0)
            dK = np.sum([p.stiffness for p in ps], axis=0)
            for k, words in FACTORS.items():
                out.append(
                    Candidate(
                        "mjed-part-derived",
                        f"MJED {KINDS[kind]} of the term {term} {words}, and the stiffness the "
                        "derivative of that force (a complex step or differences of the force "
                        "routine)",
                        k * df,
                        k * dK,
                        {"part": kind, "factor": k, "terms": term},
                    )
                )
    return out


def _gradient(parts: Parts) -> List[Candidate]:
    """A grouped term's gradient part (or that part of every term) with a constant factor where
    the term's gradient is formed: in the force and in the group's rank-one block built from it.
    """
    out = []
    for label, kind, S1, S2 in parts.gradient_blocks:
        which = f"of the term {label}" if label else "of every term"
        ps = [p for p in parts.parts if p.kind == kind and (p.term == label or not label)]
        df = np.sum([p.force for p in ps], axis=0)
        if not np.any(S1) and not np.any(S2):
            continue
        for k, words in FACTORS.items():
            out.append(
                Candidate(
                    "mjed-part",
                    f"MJED {KINDS[kind]} {which} {words} in the term's gradient, so also in the "
                    "group's rank-one block c phi''(u) du_i du_j^T built from it",
                    k * df,
                    k * S1 + k * k * S2,
                    {"part": kind + "-gradient", "factor": k, "terms": which},
                )
            )
    return out


def _dj(parts: Parts) -> List[Candidate]:
    """DJ_VARIANTS: dJ_a written wrongly, in the force and every block built from it; a block
    weighted per cell by another factor (Parts.weighted).
    """
    return (
        [
            Candidate("mjed-weighted-block", words, df, dK, {"part": "weighted", "variant": words})
            for words, df, dK in parts.weighted
        ]
        + [
            Candidate(
                "mjed-dj",
                f"MJED dJ/dx_i (dJ/dQ_i) written {words}, in the force and every stiffness block "
                "built from it",
                df,
                dK,
                {"part": "dJ", "variant": words},
            )
            for words, df, dK in parts.dj_variants
        ]
        + [
            Candidate(
                "mjed-group-shift" if words.startswith("the constant of") else "mjed-f-power",
                f"MJED {words}",
                df,
                dK,
                {"part": "f", "variant": words},
            )
            for words, df, dK in parts.power_copies
        ]
    )


def _transposed(parts: Parts) -> List[Candidate]:
    """Per term: the cross blocks written as one of them twice (its transpose left out)."""
    out = []
    for t in parts.terms:
        a = [p for p in parts.parts if p.term == t and p.kind == "cross-a"]
        b = [p for p in parts.parts if p.term == t and p.kind == "cross-b"]
        if not a or not b or not np.any(a[0].stiffness):
            continue
        d = a[0].stiffness - b[0].stiffness
        for sign, twice, lost in ((1.0, "cross-a", "cross-b"), (-1.0, "cross-b", "cross-a")):
            out.append(
                Candidate(
                    "mjed-part",
                    f"MJED {KINDS[twice]} of the term {t} written twice, its transpose "
                    f"({KINDS[lost].split(': ')[1]}) left out",
                    np.zeros_like(a[0].force),
                    sign * d,
                    {"part": "cross-transposed", "terms": t},
                )
            )
    return out


def _regularisation(parts: Parts) -> List[Candidate]:
    """The paper's regularised J-J block kept in compressed cells: of every term, or of one."""
    reg = [p for p in parts.regularised if np.any(p.stiffness)]
    pieces = [(f"of the term {p.term}", (p,)) for p in reg]
    if len(reg) > 1:
        pieces.append(("of every term", tuple(reg)))
    return [
        Candidate(
            "mjed-part",
            f"MJED {KINDS['JJ']} {which} replaced by the paper's regularised form (section 2.3: "
            "(1 - b) dJ_i dJ_j^T + b (dJ_i . dJ_j) Id, b = 1 - J) in compressed cells (J < 1)",
            np.zeros_like(ps[0].force),
            np.sum([p.stiffness for p in ps], axis=0),
            {"part": "JJ-regularised", "terms": which},
        )
        for which, ps in pieces
    ]


#: The powers of J tried for a wrong f'(J): multiples of 1/3 (the isochoric exponents).
_POWERS = tuple(np.arange(-9, 10) / 3.0)


def _frac(x: float) -> str:
    """A number as a small fraction when it is one (to 1e-9), else to 4 digits."""
    return written_number(x)


#: What f'(J) times J or divided by J is, for a volumetric term U(J): the pressure's measure.
_KIRCHHOFF_WORDS = {
    1.0: " (for a volumetric term, J U'(J) is the Kirchhoff pressure: a Kirchhoff stress used "
    "where the Cauchy stress belongs, not divided by J)",
    -1.0: " (for a volumetric term, the Cauchy pressure divided by J once more)",
}


def _df_words(t: str, k: float, p: float, q: Optional[float]) -> str:
    """The engine's f'(J) of term t, k J^p times the declared one, in words."""
    if q is None:
        if not p:
            return f"{_frac(k)} times"
        factor = "" if abs(k - 1.0) < 1e-9 else f"{_frac(k)} "
        extra = _KIRCHHOFF_WORDS.get(p, "") if not factor else ""
        return f"{factor}{_power_words(p)} times the declared f'(J){extra}"
    return (
        f"{_frac(k * q)} {_power_words(q - 1.0 + p)} for the declared {_frac(q)} "
        f"{_power_words(q - 1.0)}"
    )


#: the entry of _power that stands for every term f = J^q at once
_EVERY_POWER = "every power term J^q"


def _every_power(k: float, p: float, uniform: bool, df: np.ndarray, dK: np.ndarray) -> Candidate:
    """The candidate of every J^q term's f'(J) written k J^p times the declared c q J^(q - 1)."""
    if p == 0.0:
        words = f"{_frac(k)} times the declared c q J^(q - 1)"
    else:
        scale = "" if abs(k - 1.0) < 1e-9 else f"{_frac(k)} "
        shift = f"{'+' if p > 0 else '-'} {_frac(abs(p))}"
        words = f"{scale}c q J^(q - 1 {shift}) for the declared c q J^(q - 1)"
        if abs(k - 1.0) < 1e-9 and p == 1.0:
            words += " (the exponent not lowered: c q J^q)"
    if uniform:
        words += " (J is the same in every cell here: whether the factor follows a power of J "
        words += "cannot be told)"
    return Candidate(
        "mjed-dfdj",
        f"MJED f'(J) of every power term c J^q written wrongly (force and stiffness): {words}",
        df,
        dK,
        {"part": "dfdJ", "terms": _EVERY_POWER, "k": k, "p": p},
    )


def _power(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Per term: f'(J) wrong by a per-cell factor k J^p (p in _POWERS, k fitted by least
    squares on the scaled residual r (3n + p,), weights w (3n + p,)): the J part of the force and
    the f'-blocks scaled together. With J the same in every cell only p = 0 is tried (a power
    cannot be told from a constant there).
    """
    pat, J = parts.pattern, parts.J
    uniform = np.ptp(J) <= 1e-9 * np.mean(np.abs(J))
    powers = dict(parts.powers)
    out = []
    entries = list(parts.df_cells)
    every = [(fe, Ke) for t, fe, Ke in parts.df_cells if t in powers]
    if len(every) > 1:
        # one hand-written power rule shared by every J^q term (a helper that returns f')
        entries.append((_EVERY_POWER, sum(e[0] for e in every), sum(e[1] for e in every)))
    for t, fe, Ke in entries:
        one = np.ones_like(J)
        P = np.concatenate([pat.force(fe, one), pat.stiffness(Ke, one)])  # as the oracle's
        if not np.any(P):
            continue
        for p in (0.0,) if uniform else _POWERS:
            Jp = J**p
            X = np.concatenate([pat.force(fe, Jp), pat.stiffness(Ke, Jp)])
            xs = X * w
            k = float(xs @ ((r + P) * w) / (xs @ xs))
            if not np.isfinite(k) or (p == 0.0 and abs(k - 1.0) < 1e-9):
                continue
            d = k * X - P
            n = 3 * pat.n
            if t is _EVERY_POWER:
                out.append(_every_power(k, p, uniform, d[:n], d[n:]))
                continue
            words = _df_words(t, k, p, powers.get(t))
            j = float(np.mean(J))
            power = next((q for q in (1.0, -1.0) if abs(k - j**q) <= 1e-6 * max(k, 1e-300)), None)
            if uniform and powers.get(t) is None and power is not None:
                words = (
                    f"{_df_words(t, 1.0, power, None)}, or equally {words}: J = {j:.6g} in "
                    "every cell here, which cannot tell a power of J from a constant"
                )
            elif uniform:
                words += " (J is the same in every cell here: whether the factor follows a "
                words += "power of J cannot be told)"
            out.append(
                Candidate(
                    "mjed-dfdj",
                    f"MJED f'(J) of the term {t} written wrongly (force and stiffness): {words}",
                    d[:n],
                    d[n:],
                    {"part": "dfdJ", "terms": t, "k": k, "p": p},
                )
            )
    return out


def _d2f(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Per term: f''(J) written k times the declared one (k fitted by least squares on the
    scaled stiffness residual; a power rule slipped in a hand second derivative, q (q + 1)
    for q (q - 1) say) or k J^p times it (:func:`_d2f_powers`): the J-J block alone changes.
    Constant factors of the block that :data:`FACTORS` says in words are left to _single.
    """
    if np.ptp(parts.J) <= 1e-6 * np.mean(np.abs(parts.J)):
        # one J (a homogeneous state): every term's J-J block, and any term along
        # C^-1 (x) C^-1, has the same shape; a fitted factor cannot tell which
        return []
    n = 3 * parts.pattern.n
    powers = dict(parts.powers)
    out = []
    for p in parts.parts:
        if p.kind != "JJ" or not np.any(p.stiffness):
            continue
        xs = p.stiffness * w[n:]
        c = float(xs @ (r[n:] * w[n:]) / (xs @ xs))
        if not np.isfinite(c) or any(abs(c - k) <= 1e-9 * max(1.0, abs(k)) for k in FACTORS):
            continue
        k, q = 1.0 + c, powers.get(p.term)
        if q is None:
            words = f"{_frac(k)} times the declared f''(J)"
        else:
            words = (
                f"{_frac(k * q * (q - 1.0))} {_power_words(q - 2.0)} where the declared "
                f"f = {_power_words(q)} has {_frac(q * (q - 1.0))} {_power_words(q - 2.0)}"
            )
        out.append(
            Candidate(
                "mjed-d2f",
                f"MJED f''(J) of the term {p.term} written wrongly (the J-J block f'' g "
                f"dJ_i dJ_j^T alone; force right): {words}",
                np.zeros(n),
                c * p.stiffness,
                {"part": "d2fdJ2", "terms": p.term, "k": k},
            )
        )
    return out + _d2f_powers(parts, r, w)


def _d2f_powers(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Per term: f''(J) written k J^p times the declared one, p in _POWERS but not 0, k fitted
    (the exponent of a power J^q lowered once, not twice: q (q - 1) J^(q - 1), p = 1). Only
    where J varies (the caller's test): on one J a power of J is a constant factor.
    """
    pat, J = parts.pattern, parts.J
    n = 3 * pat.n
    powers = dict(parts.powers)
    out = []
    for t, _, Ke in parts.d2f_cells:
        P = pat.stiffness(Ke, np.ones_like(J))
        if not np.any(P):
            continue
        for p in _POWERS:
            if p == 0.0:
                continue
            X = pat.stiffness(Ke, J**p)
            xs = X * w[n:]
            k = float(xs @ ((r[n:] + P) * w[n:]) / (xs @ xs))
            if not np.isfinite(k) or k == 0.0:
                continue
            q = powers.get(t)
            if q is None:
                words = f"{_frac(k)} {_power_words(p)} times the declared f''(J)"
            else:
                words = (
                    f"{_frac(k * q * (q - 1.0))} {_power_words(q - 2.0 + p)} where the declared "
                    f"f = {_power_words(q)} has {_frac(q * (q - 1.0))} {_power_words(q - 2.0)}"
                )
            out.append(
                Candidate(
                    "mjed-d2f",
                    f"MJED f''(J) of the term {t} written wrongly (the J-J block f'' g "
                    f"dJ_i dJ_j^T alone; force right): {words}",
                    np.zeros(n),
                    k * X - P,
                    {"part": "d2fdJ2", "terms": t, "k": k, "p": p},
                )
            )
    return out


#: The largest step read as a difference quotient's (in the units of J or u, both O(1)): a
#: fitted "step" beyond it is a factor, not a truncation.
_MAX_STEP = 1e-2


def _differences(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Per scalar derivative (Parts.differences): taken by a forward (or backward) difference
    of the function below it with step h, which adds h/2 (or -h/2) times the next derivative
    wherever it enters; h fitted. On one J the f''(J) blocks of all terms share one shape, so
    those are not tried there.
    """
    one_j = np.ptp(parts.J) <= 1e-6 * np.mean(np.abs(parts.J))
    out = []
    for what, of, X, X2 in parts.differences:
        if one_j and what.startswith("f''"):
            continue
        # engine minus right = (h/2) X + (h^2/6) X2 for a forward step h (c = h/2; backward:
        # c = -h/2, the same h^2 term): c fitted, then refitted with the h^2 term held
        xs = X * w
        c = float(xs @ (r * w) / (xs @ xs))
        for _ in range(3):
            c = float(xs @ ((r - (2.0 / 3.0) * c * c * X2) * w) / (xs @ xs))
        h = 2.0 * abs(c)
        if not np.isfinite(c) or c == 0.0 or h > _MAX_STEP:
            continue
        X = X + (2.0 / 3.0) * c * X2  # so that c X is the prediction
        scheme = "forward" if c > 0 else "backward"
        n = 3 * parts.pattern.n
        out.append(
            Candidate(
                "mjed-difference",
                f"MJED {what} taken by a {scheme} difference of {of} with step h = {h:.2g} (the "
                "derivative plus h/2 times the next one: an O(h) truncation error)",
                c * X[:n],
                c * X[n:],
                {
                    "part": "difference",
                    "derivative": what,
                    "scheme": scheme,
                    "step": h,
                    # f'' enters the J-J block alone: along dJ (x) dJ (corroborate.fits_codes)
                    **({"invariant": "J"} if what.startswith("f''") else {}),
                },
            )
        )
    return out


#: stiffness blocks of one term that a hand tangent types apart from the force -> (the kinds,
#: what is written k times, whether one J (a homogeneous state) can tell terms apart there).
_TYPED_APART: Dict[str, Tuple[Tuple[str, ...], str, bool]] = {
    "dfdJ-blocks": (
        ("cross-a", "cross-b", "anti"),
        "f'(J) in its stiffness blocks alone (the cross blocks and the antisymmetric block; "
        "the force's f' right)",
        True,
    ),
    "geometric": (
        ("geometric",),
        "in its geometric block f(J) (D_i . S D_j) Id alone (the force's S right)",
        False,
    ),
    "material": (
        ("first", "second-outer", "second-scaled", "spectral"),
        "in its material blocks alone (d2g/dC2, the force right)",
        False,
    ),
}


def _typed_apart(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Per term and per group of :data:`_TYPED_APART`: those stiffness blocks written k times
    (k fitted on the scaled stiffness residual), the force right: a factor typed a second time
    in the tangent's code. A group of one kind with a factor of :data:`FACTORS` is _single's;
    on one J, groups whose terms' blocks share a shape there are not tried.
    """
    n = 3 * parts.pattern.n
    one_j = np.ptp(parts.J) <= 1e-6 * np.mean(np.abs(parts.J))
    out = []
    for code, (kinds, words, on_one_j) in _TYPED_APART.items():
        blocks = {}
        for t in parts.terms:
            ps = [p for p in parts.parts if p.term == t and p.kind in kinds]
            if any(np.any(p.stiffness) for p in ps):
                blocks[t] = (ps, np.sum([p.stiffness for p in ps], axis=0))
        for t, (ps, P) in blocks.items():
            if one_j and (
                not on_one_j
                and any(_parallel(P, Q) for u, (_, Q) in blocks.items() if u != t)
                or any(
                    _parallel(P, q.stiffness) for u, (qs, _) in blocks.items() if u != t for q in qs
                )
            ):
                # one J: another term's blocks of these kinds, or one of them (the J-Hessian
                # blocks of all terms share one shape there), have the same shape
                continue
            xs = P * w[n:]
            c = float(xs @ (r[n:] * w[n:]) / (xs @ xs))
            if not np.isfinite(c):
                continue
            if len([p for p in ps if np.any(p.stiffness)]) == 1 and any(
                abs(c - k) <= 1e-9 * max(1.0, abs(k)) for k in FACTORS
            ):
                continue
            out.append(
                Candidate(
                    "mjed-typed-apart",
                    f"MJED the term {t} written {_frac(1.0 + c)} times {words}",
                    np.zeros(n),
                    c * P,
                    {"part": code, "terms": t, "k": 1.0 + c},
                )
            )
    return out


def _parallel(a: np.ndarray, b: np.ndarray) -> bool:
    """True when the vectors a and b are parallel to 1e-9 (their angle's cosine)."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    return na > 0 and nb > 0 and abs(float(a @ b)) >= (1.0 - 1e-9) * na * nb


#: power p of J -> words: a term's force and stiffness scaled cell by cell by J^p.
VOLUME_WORDS = {1.0: "times J (integrated over the deformed volume J V)", -1.0: "divided by J"}


def _volume(parts: Parts) -> List[Candidate]:
    """Per term: its whole force and stiffness scaled cell by cell by J (integrated over the
    deformed volume J V) or 1/J, the other terms right. Only where J varies from cell to cell (a
    single J is a constant factor, the term-coefficient reading's).
    """
    pat, J = parts.pattern, parts.J
    if np.ptp(J) <= 1e-9 * np.mean(np.abs(J)):
        return []
    out = []
    for t, fe, Ke in parts.term_cells:
        for p, words in VOLUME_WORDS.items():
            w = J**p - 1.0
            out.append(
                Candidate(
                    "mjed-term-volume",
                    f"the term {t}: its force and stiffness {words}, cell by cell; the other "
                    "terms right",
                    pat.force(fe, w),
                    pat.stiffness(Ke, w),
                    {"part": "volume", "terms": t, "p": p},
                )
            )
    return out


def _j_tensor(model: Any, points, cells, x, pat: Pattern) -> List[Candidate]:
    """The J part of a term's stress with another tensor than C^-1
    (:mod:`conformance.diagnosis.pressure_tensor`): the force alone changes.
    """
    from conformance.diagnosis.pressure_tensor import j_tensor_forces

    found = j_tensor_forces(
        model,
        points,
        cells,
        x,
        lambda term, group: term_label(term) + _group_words(group),
        pat.force,
    )
    zero = np.zeros(len(pat.rows))
    return [
        Candidate(
            "mjed-j-tensor",
            f"the stress's J part f'(J) g J C^-1 {which} written with {tensor} where C^-1 "
            "belongs (the force; the stiffness as the engine's tangent has it)",
            df,
            zero,
            {"part": "J-tensor", "terms": which, "tensor": tensor.split(" (")[0]},
        )
        for which, tensor, df in found
    ]


def candidates(parts: Parts, r: np.ndarray, w: np.ndarray) -> List[Candidate]:
    """Every reading's predicted engine-minus-oracle, the most specific first; r (3n + p,) the
    residual and w (3n + p,) its weights (1 / scale), for the fitted factor of _power.
    """
    return [
        *_single(parts),
        *_derived(parts),
        *_gradient(parts),
        *_transposed(parts),
        *_power(parts, r, w),
        *_d2f(parts, r, w),
        *_typed_apart(parts, r, w),
        *_differences(parts, r, w),
        *_regularisation(parts),
        *_dj(parts),
        *_volume(parts),
    ]


def mjed_part_findings(
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
    force_alone: bool = False,
) -> Optional[List[Finding]]:
    """The readings whose prediction, added to the oracle's force f_o (n, 3) and stiffness K_o
    (3n, 3n), brings the engine's f, K within ``tol`` (ambiguous when several predict
    differently); None when the model's parts cannot be built or do not add up to the oracle.
    force_alone: where none does and the force is wrong, those that give the force alone, said
    partly (the last reading of a force-wrong case: an exact reading of both goes first).
    """
    parts = mjed_parts(model, points, cells, x, f_o, K_o)
    if parts is None:
        return None
    pat = parts.pattern
    force_right = errors(f, sp.csr_matrix(K_o), None, f_o, K_o, 0.0, s).force <= tol.force
    if not force_right:
        # a term's f(J) with another power changes the force: read only where it is wrong
        f_sum = np.sum([p.force for p in parts.parts], axis=0)
        K_sum = np.sum([p.stiffness for p in parts.parts], axis=0)
        st = _State(points, cells, x, pat, f_sum, K_sum)
        copies = _power_copies(model, st) + _shift_copies(model, st)
        parts = replace(parts, power_copies=copies)
    f_o = np.asarray(f_o, dtype=np.float64)
    r, w, off = residual(pat, f, K, f_o, K_o, s)
    cands = list(candidates(parts, r, w))
    if not force_right:
        cands += _j_tensor(model, points, cells, x, pat)
    same: Dict[int, List[str]] = {}
    kept = explaining(cands, r, w, off, 3 * pat.n, tol, same)
    if kept or not force_alone or force_right:
        return ambiguous(
            [with_equals(part_finding(c, d, f, K, f_o, K_o, pat, s), same, c) for c, d in kept]
        )
    # The force alone predicted: the stiffness carries a slip of its own (a hand tangent
    # written apart from the force), which a force part's derived blocks do not give.
    loose = replace(tol, stiffness=1e300)  # the stiffness not asked of the prediction
    n = 3 * pat.n
    k_right = errors(f, K, None, f, K_o, 0.0, s).stiffness <= tol.stiffness
    forces: List[np.ndarray] = []
    found = []
    for c, d in explaining(cands, r, w, 0.0, n, loose):
        if not np.any(c.force) or any(np.allclose(c.force, g, rtol=1e-9, atol=0) for g in forces):
            continue  # the same force said once: its derived blocks are what differ
        forces.append(c.force)
        found.append(force_only(part_finding(c, d, f, K, f_o, K_o, pat, s), k_right))
    return ambiguous(found)


def with_equals(found: Finding, same: Dict[int, List[str]], c: Any) -> Finding:
    """``found`` with the readings whose prediction is the same here added to its evidence."""
    equals = same.get(id(c))
    if not equals:
        return found
    return replace(
        found,
        evidence=found.evidence + "; equally (the same prediction here): " + "; ".join(equals),
    )


def force_only(found: Finding, stiffness_right: bool) -> Finding:
    """A part reading that predicts the force alone, said as partly explaining; the engine's
    stiffness is the oracle's (``stiffness_right``: the energy's tangent, not this force's) or
    carries a slip of its own, left unexplained.
    """
    said = (
        "your stiffness is right (the energy's), so it is not this force's derivative"
        if stiffness_right
        else "your stiffness is not this force's (a slip of its own, left unexplained)"
    )
    return replace(
        found,
        title=f"your force: {found.title}; {said}",
        strength=PARTIAL,
        evidence=found.evidence + " (the force alone predicted)",
    )


def residual(
    pat: Pattern, f: np.ndarray, K: Any, f_o: np.ndarray, K_o: Any, s: Scales
) -> Tuple[np.ndarray, np.ndarray, float]:
    """The engine-minus-oracle force and stiffness on the element pattern r (3n + p,), its
    weights w (1 / scale, 3n + p,) and the scaled norm of the engine's entries off the pattern
    (the oracle's K_o has none there).
    """
    on_e, off_e = sparse_entries(K, pat)
    on_o, _ = sparse_entries(K_o, pat)
    n = 3 * pat.n
    f_o = np.asarray(f_o, dtype=np.float64)
    r = np.concatenate([(np.asarray(f, dtype=np.float64) - f_o).ravel(), on_e - on_o])
    w = np.concatenate([np.full(n, 1.0 / s.force), np.full(len(on_e), 1.0 / s.stiffness)])
    return r, w, float(np.sqrt(off_e + 0.0) / s.stiffness)


def explaining(
    cands: Any,
    r: np.ndarray,
    w: np.ndarray,
    off: float,
    n: int,
    tol: Tolerances,
    same: Optional[Dict[int, List[str]]] = None,
) -> List[Tuple[Any, np.ndarray]]:
    """(candidate, its prediction (3n + p,)) of every candidate (with .force (n,) and .stiffness)
    whose prediction brings the residual r within ``tol``, in order; a prediction the same as
    one kept (to _SAME of the residual) is left out: one cause said once. same: filled with
    id(kept candidate) -> the titles of those left out as its equals.
    """
    kept: List[Tuple[Any, np.ndarray]] = []
    scale = max(np.linalg.norm(r * w), 1e-300)
    for c in cands:
        d = np.concatenate([c.force, c.stiffness])
        e = (r - d) * w
        ef, eK = np.linalg.norm(e[:n]), np.hypot(np.linalg.norm(e[n:]), off)
        if ef > tol.force or eK > tol.stiffness:
            continue
        twin = next((k for k, d2 in kept if np.linalg.norm((d - d2) * w) <= _SAME * scale), None)
        if twin is not None:
            if same is not None and c.title != twin.title:
                same.setdefault(id(twin), []).append(c.title)
            continue
        kept.append((c, d))
    return kept


#: What mjed_parts' predictions are, in a finding's evidence.
_SOURCE = (
    "this part's contribution (from mjed's declared terms, which add up to the oracle to round-off)"
)


def part_finding(c, d, f, K, f_o, K_o, pat, s: Scales, source: str = _SOURCE) -> Finding:
    """A reading (code, title, figures) with its prediction d (3n + p,) as a finding, its
    errors checked on the assembled matrices; source: what the prediction is, in words.
    """
    n = 3 * pat.n
    dK = sp.csr_matrix((d[n:], (pat.rows, pat.cols)), shape=(n, n))
    e = errors(f, K, None, f_o + d[:n].reshape(-1, 3), sp.csr_matrix(K_o) + dK, 0.0, s)
    return Finding(
        c.code,
        c.title,
        FULL,
        f"the oracle's force and stiffness plus {source} match the engine: force error "
        f"{e.force:.1e}, stiffness {e.stiffness:.1e}",
        {**c.figures, "force_error": e.force, "stiffness_error": e.stiffness},
    )


def mjed_part_reading(
    diag: Any, ci: Any, out: Any, ref: Any, s: Scales, force_alone: bool = False
) -> Any:
    """``diag`` with the MJED part reading named first when one explains the engine; unchanged
    otherwise. A material mjed cannot split (or too large a mesh) gets
    :func:`conformance.diagnosis.j_hessian_block.j_hessian_reading` instead, from the declared
    energy's formula. force_alone: see :func:`mjed_part_findings`. Where nothing is found on the
    model's own terms, its power groups expanded term by term
    (:mod:`conformance.diagnosis.expanded_terms`) are read the same way.
    """
    case = (ci.points, ci.cells, ci.positions, out.force, out.stiffness, ref.force, ref.stiffness)
    found = mjed_part_findings(ci.model, *case, s, diag.tolerances, force_alone)
    if found is None:
        if force_alone:
            return diag
        return j_hessian_reading(diag, ci, out, ref, s)
    if not found:
        found = _expanded_findings(ci.model, case, s, diag.tolerances, force_alone)
    if not found:
        # the Hessian of J itself built wrongly (from F's rows), which no part's factor is
        return diag if force_alone else j_hessian_reading(diag, ci, out, ref, s)
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])


def _expanded_findings(model: Any, case: tuple, s: Scales, tol: Tolerances, force_alone: bool):
    """The part readings on ``model`` with its power groups expanded, each said so; [] when
    nothing expands or nothing is found.
    """
    from conformance.diagnosis.expanded_terms import expanded_model

    expanded = expanded_model(model)
    if expanded is None:
        return []
    found = mjed_part_findings(expanded, *case, s, tol, force_alone) or []
    said = (
        " (the energy's power groups expanded term by term, c (I1b - 3)^k by the binomial "
        "theorem into terms J^(-2j/3) I1^j, as your engine writes them)"
    )
    return [replace(f, title=f.title + said) for f in found]
