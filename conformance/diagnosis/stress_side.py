"""A stress written wrongly by hand while the tangent is derived separately.

A UMAT-style or total-Lagrangian engine computes the stress S and the material tangent CC
(dS/dC, DDSDDE) as two formulas and assembles the force from S and the stiffness as the
geometric part (D_i . S D_j) Id, from that same S, plus the material part F CC F^T. When the
stress formula is wrong and the tangent formula right, the force and the geometric stiffness
follow the wrong stress and the material stiffness does not: no energy, and no single wrong part
of an MJED engine (:mod:`conformance.diagnosis.mjed_parts`, whose geometric block is its own
part), explains it.

The pieces are built per cell from mjed's declared terms f(J) g(C) (groups c phi(u) of them),
as :mod:`conformance.diagnosis.mjed_parts` builds its parts, and used only when they add up to
the oracle's force and stiffness to round-off. Per term (a polynomial in ln J split into its
monomials, each its own coefficient): its stress-side pieces, the force and the geometric block
of its stress (the C part f S, and the J part f' g J C^-1, whose geometric block is
f' g (dJ_i . dJ_j) / J Id). Two families:

- **a term's coefficient wrong in the stress only**: one coefficient per term fitted on the
  stress-side pieces (least squares), the material tangent fixed at 1;
- **a group's gradient part wrong by a factor k** (the J part f' g dJ or the C part f dg of one
  grouped term's du, k fitted): the stress c phi'(u) du and the group's rank-one tangent part
  c phi''(u) du (x) du built from the wrong du, the Hessian of u right; or, beside it, the
  Hessian's terms linear in f' (the cross blocks and the dC^-1/dC block) scaled by k too, the
  f'^2 term right (a derivative of f(J) written wrongly where it is written, in dQh/dC and in
  d2Qh/dC2).

A reading is named only when its prediction brings force and stiffness within the case's
tolerance; several that predict differently are shown as ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import ambiguous
from conformance.diagnosis.fractions import written_number
from conformance.diagnosis.least_squares import determined_lstsq
from conformance.diagnosis.mjed_parts import (
    MAX_CELLS,
    Candidate,
    Pattern,
    explaining,
    mjed_parts,
    part_finding,
    residual,
    term_label,
)
from conformance.diagnosis.parameters import scalar_parameters
from conformance.judge.compare import Scales, Tolerances

__all__ = [
    "Piece",
    "Gradient",
    "StressSide",
    "stress_side",
    "stress_candidates",
    "stress_side_findings",
    "stress_side_reading",
]

#: A fitted coefficient this close to 1 (relative) is 1.
_ONE = 1e-6
#: Columns of the coefficient fit with a singular value below this (relative) are not separated.
_IDENTIFIED = 1e-8


@dataclass(frozen=True)
class Piece:
    """One term's stress side: its label, its coefficient (the monomial's, for the parameter's
    name) and its force (3n,, as the oracle's -dW/dx) and geometric stiffness (p,).
    """

    label: str
    coefficient: Optional[float]
    force: np.ndarray
    geometric: np.ndarray


@dataclass(frozen=True)
class Gradient:
    """One grouped term's gradient part (kind "J" or "C") wrong by k = 1 + t: the change is
    t linear + t^2 quadratic (each (3n + p,)); hessian (p,): the Hessian's blocks linear in the
    part (J part: the cross blocks and the dC^-1/dC block), for the variant that scales them too.
    q: f = J^q of the term (None for another f).
    """

    label: str
    kind: str
    linear: np.ndarray
    quadratic: np.ndarray
    hessian: Optional[np.ndarray]
    q: Optional[float]


@dataclass(frozen=True)
class StressSide:
    """A case's stress-side pieces and grouped gradients on the element pattern."""

    pattern: Pattern
    pieces: Tuple[Piece, ...]
    gradients: Tuple[Gradient, ...]


def _split_terms(term: Any) -> List[Tuple[Any, Optional[float]]]:
    """A term as (term, coefficient) pieces: a polynomial in ln J as its monomials."""
    from mjed.terms import I1Power, LinearI2, LogPolynomial, Term

    f, g = term.f, term.g
    if isinstance(f, LogPolynomial):
        mono = [LogPolynomial(f.a2, 0.0, 0.0), LogPolynomial(0.0, f.a1, 0.0)]
        return [(Term(p, g), c) for p, c in zip(mono, (f.a2, f.a1)) if c]
    coefficient = getattr(g, "c", None) if isinstance(g, (I1Power, LinearI2)) else None
    return [(term, coefficient)]


def _mono_label(term: Any) -> str:
    """A monomial of ln J in words, else the term's label."""
    from mjed.terms import LogPolynomial

    if isinstance(term.f, LogPolynomial):
        return "(ln J)^2 (volumetric)" if term.f.a2 else "ln J (volumetric)"
    return term_label(term)


def _sides(term: Any, kin: Any, F: np.ndarray, D: np.ndarray, dJ: np.ndarray) -> Dict[str, Any]:
    """One term's pieces per cell without the group's factor: force-J, force-C (m, 4, 3), the
    geometric blocks of the C and J parts, the cross blocks and dJ_j dJ_i^T f' g / J
    (m, 4, 3, 4, 3).
    """
    m = F.shape[0]
    J = kin.J
    f, f1, _ = (np.broadcast_to(np.asarray(v, dtype=np.float64), (m,)) for v in term.f(J))
    g = np.broadcast_to(np.asarray(term.g.value(kin), dtype=np.float64), (m,))
    S = term.g.stress(kin)
    S = np.zeros((m, 3, 3)) if S is None else np.broadcast_to(S, (m, 3, 3))
    FSD = np.einsum("mik,mkl,mal->mai", F, S, D)
    c = (slice(None), None, None, None, None)
    eye = np.eye(3)
    return {
        "force-J": (f1 * g)[:, None, None] * dJ,
        "force-C": f[:, None, None] * FSD,
        "geometric-C": f[c] * np.einsum("mak,mkl,mbl,ij->maibj", D, S, D, eye),
        "geometric-J": (f1 * g / J)[c] * np.einsum("mak,mbk,ij->maibj", dJ, dJ, eye),
        "cross": f1[c]
        * (np.einsum("mai,mbj->maibj", dJ, FSD) + np.einsum("mai,mbj->maibj", FSD, dJ)),
        "transposed": (f1 * g / J)[c] * np.einsum("mbi,maj->maibj", dJ, dJ),
        "value": f * g,
    }


def _outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("mai,mbj->maibj", u, v)


def _group(group: Any, kin, F, D, dJ, pat: Pattern, V0: np.ndarray):
    """One group's pieces and gradients (assembled)."""
    from mjed.terms import JPower

    m = F.shape[0]
    sides = [_sides(t, kin, F, D, dJ) for t in group.terms]
    w1, w2 = group.coefficient, 0.0
    if not group.plain:
        u = np.sum([s["value"] for s in sides], axis=0)
        _, d1, d2 = group.function(u)
        w1, w2 = group.coefficient * d1, group.coefficient * d2
    w1 = np.broadcast_to(np.asarray(w1, dtype=np.float64), (m,))
    w2 = np.broadcast_to(np.asarray(w2, dtype=np.float64), (m,))
    c = (slice(None), None, None, None, None)
    suffix = "" if group.plain else f" (in the group c {type(group.function).__name__.lower()}(u))"
    pieces = []
    for term in group.terms:
        for mono, coefficient in _split_terms(term):
            s = _sides(mono, kin, F, D, dJ)
            fe = w1[:, None, None] * (s["force-J"] + s["force-C"])
            Ke = w1[c] * (s["geometric-C"] + s["geometric-J"])
            label = _mono_label(mono) + suffix
            pieces.append(Piece(label, coefficient, -pat.force(fe, V0), pat.stiffness(Ke, V0)))
    gradients = []
    if not group.plain:
        du = np.sum([s["force-J"] + s["force-C"] for s in sides], axis=0)
        n = 3 * pat.n
        for term, s in zip(group.terms, sides):
            q = float(term.f.p) if isinstance(term.f, JPower) else None
            for kind in ("J", "C"):
                a = s["force-" + kind]
                if not np.any(a):
                    continue
                S1 = w2[c] * (_outer(a, du) + _outer(du, a)) + w1[c] * s["geometric-" + kind]
                lin = np.concatenate([-pat.force(w1[:, None, None] * a, V0), pat.stiffness(S1, V0)])
                quad = np.concatenate([np.zeros(n), pat.stiffness(w2[c] * _outer(a, a), V0)])
                hess = None
                if kind == "J":
                    blocks = s["cross"] - s["transposed"] - s["geometric-J"]
                    hess = pat.stiffness(w1[c] * blocks, V0)
                gradients.append(Gradient(term_label(term) + suffix, kind, lin, quad, hess, q))
    return pieces, gradients


def stress_side(
    model: Any, points: np.ndarray, cells: np.ndarray, x: np.ndarray, f_o, K_o
) -> Optional[StressSide]:
    """The stress-side pieces of ``model`` at positions x (n, 3), or None where mjed's parts do
    not add up to the oracle's force f_o (n, 3) and stiffness K_o (what the pieces are checked
    against: the pieces are theirs, regrouped), or the stress pieces not to its force.
    """
    from mjed.kinematics import Kinematics

    if cells.shape[0] > MAX_CELLS or mjed_parts(model, points, cells, x, f_o, K_o) is None:
        return None
    V0, D, F = cell_kinematics(points, cells, x)
    kin = Kinematics(F)
    dJ = kin.J[:, None, None] * np.einsum("mji,maj->mai", np.linalg.inv(F), D)
    pat = Pattern.of(cells, points.shape[0])
    pieces: List[Piece] = []
    gradients: List[Gradient] = []
    for group in model.decomposition():
        p, g = _group(group, kin, F, D, dJ, pat, V0)
        pieces += p
        gradients += g
    f_sum = np.sum([p.force for p in pieces], axis=0)
    f_ref = np.asarray(f_o, dtype=np.float64).ravel()
    scale = max(np.linalg.norm(f_ref), max(np.linalg.norm(p.force) for p in pieces), 1e-300)
    if np.linalg.norm(f_sum - f_ref) > 1e-9 * scale:
        return None
    return StressSide(pat, tuple(pieces), tuple(gradients))


def _fraction(x: float) -> str:
    return written_number(x, rtol=1e-6)


def _parameter(c: Optional[float], params: Dict[str, float]) -> Optional[Tuple[str, Fraction]]:
    """The one parameter p with c = r p, r a small fraction (None if none or several)."""
    if c is None:
        return None
    found = []
    for name, v in params.items():
        if v:
            r = Fraction(c / v).limit_denominator(6)
            if r and abs(float(r) - c / v) <= 1e-9 * abs(c / v) and abs(r.numerator) <= 6:
                found.append((name, r))
    return found[0] if len(found) == 1 else None


def _coefficient_words(k: np.ndarray, off: List[int], pieces, params) -> str:
    """The stress-only coefficients k (one per piece) in words: by parameter where the pieces
    off 1 are one parameter's, sharing one factor; else per term.
    """
    named = [_parameter(pieces[i].coefficient, params) for i in off]
    names = {n[0] for n in named if n}
    ks = k[off]
    if len(names) == 1 and all(named) and np.ptp(ks) <= _ONE * max(1.0, abs(ks[0])):
        p, factor = names.pop(), _fraction(float(ks[0]))
        terms = ", ".join(pieces[i].label for i in off)
        written = f"{p}/{factor[2:]}" if factor.startswith("1/") else f"{factor} {p}"
        return (
            f"{written} where {p} belongs in the stress (factor {factor} on the stress of the "
            f"{p} terms: {terms})"
        )
    return "; ".join(
        f"the stress of the term {pieces[i].label} times {_fraction(float(k[i]))}" for i in off
    )


def _columns(pieces, params) -> List[List[List[int]]]:
    """The ways the pieces' coefficients are fitted: one per piece; one per parameter (a
    parameter's pieces scaled together, which a state with one J in every cell separates where
    it cannot tell (ln J)^2 from ln J).
    """
    by: Dict[str, List[int]] = {}
    for i, p in enumerate(pieces):
        named = _parameter(p.coefficient, params)
        by.setdefault(named[0] if named else f"#{i}", []).append(i)
    per_piece = [[i] for i in range(len(pieces))]
    per_parameter = list(by.values())
    return [per_piece] + ([per_parameter] if len(per_parameter) < len(pieces) else [])


def _fit(side: StressSide, cols: List[List[int]], r, w) -> Optional[np.ndarray]:
    """Per piece the fitted coefficient (pieces of one column share one), None where the
    columns are not separated on this case.
    """
    P = [np.concatenate([p.force, p.geometric]) for p in side.pieces]
    X = np.column_stack([np.sum([P[i] for i in c], axis=0) for c in cols])
    t = determined_lstsq(X * w[:, None], r * w, _IDENTIFIED)
    if t is None:
        return None
    k = np.ones(len(P))
    for c, tc in zip(cols, t):
        k[c] = 1.0 + tc
    return k


def _coefficients(side: StressSide, r, w, params, energy_right: bool) -> List[Candidate]:
    """One coefficient per term (or per parameter) on its stress-side pieces, the material
    tangent at 1.
    """
    n = 3 * side.pattern.n
    rest = "; the material tangent" + (" and the energy right" if energy_right else " right")
    out = []
    for cols in _columns(side.pieces, params):
        k = _fit(side, cols, r, w)
        off = [] if k is None else [i for i, ki in enumerate(k) if abs(ki - 1.0) > _ONE]
        if not off:
            continue
        d = np.sum(
            [
                (k[i] - 1.0) * np.concatenate([p.force, p.geometric])
                for i, p in enumerate(side.pieces)
            ],
            axis=0,
        )
        out.append(
            Candidate(
                "stress-coefficient",
                "a stress written wrongly, its tangent right: "
                + _coefficient_words(k, off, side.pieces, params)
                + rest
                + " (the force and the geometric stiffness follow the stress, the material "
                "stiffness does not)",
                d[:n],
                d[n:],
                {"part": "stress-coefficients", "coefficients": [float(v) for v in k]},
            )
        )
    return out


def _best_t(y: np.ndarray, a: np.ndarray, b: np.ndarray) -> Optional[float]:
    """The t minimising ||y - t a - t^2 b|| (the real root of the cubic with the least cost)."""
    ya, yb, aa, ab, bb = y @ a, y @ b, a @ a, a @ b, b @ b
    roots = np.roots([4.0 * bb, 6.0 * ab, 2.0 * (aa - 2.0 * yb), -2.0 * ya])
    real = [float(z.real) for z in roots if abs(z.imag) <= 1e-9 * max(1.0, abs(z))]
    if not real:
        return None
    cost = [np.linalg.norm(y - t * a - t * t * b) for t in real]
    return real[int(np.argmin(cost))]


def _gradient_words(g: Gradient, k: float, hessian: bool) -> str:
    """A grouped term's gradient part wrong by k, in words."""
    kf = _fraction(k)
    if g.kind == "J" and g.q is not None:
        h = g.q / 2.0
        jq = f"J^({_fraction(g.q)})"
        what = (
            f"the derivative of {jq} in the gradient du/dC of the term {g.label} written "
            f"{_fraction(k * h)} {jq} g C^-1 where {_fraction(h)} {jq} g C^-1 belongs "
            f"(factor {kf} on the J part of the term's gradient)"
        )
    elif g.kind == "J":
        what = f"f'(J) in the J part of the gradient of the term {g.label} times {kf}"
    else:
        what = f"the C part f dg/dC of the gradient of the term {g.label} times {kf}"
    where = (
        ", in the stress (force and geometric stiffness) and in the rank-one part "
        "c phi''(u) du (x) du of the tangent"
    )
    if hessian:
        return (
            what
            + where
            + (
                "; in the second derivative d2u/dC2 too (its terms linear in that derivative: the "
                "cross terms and the dC^-1/dC term), its squared term right"
            )
        )
    return what + where + "; the second derivative d2u/dC2 right"


def _gradients(side: StressSide, r, w) -> List[Candidate]:
    """Each grouped term's gradient part with a fitted factor k, its Hessian right or its
    Hessian's linear terms scaled too.
    """
    n = 3 * side.pattern.n
    out = []
    for g in side.gradients:
        variants = [(False, g.linear)]
        if g.hessian is not None:
            variants.append((True, g.linear + np.concatenate([np.zeros(n), g.hessian])))
        for hessian, lin in variants:
            t = _best_t(r * w, lin * w, g.quadratic * w)
            if t is None or abs(t) <= _ONE:
                continue
            d = t * lin + t * t * g.quadratic
            out.append(
                Candidate(
                    "stress-gradient",
                    "a stress written wrongly, its tangent partly: "
                    + _gradient_words(g, 1.0 + t, hessian),
                    d[:n],
                    d[n:],
                    {"part": f"gradient-{g.kind}", "k": 1.0 + t, "hessian": hessian},
                )
            )
    return out


def stress_candidates(side: StressSide, r, w, params, energy_right: bool) -> List[Candidate]:
    """Every reading's predicted engine-minus-oracle (force (3n,), stiffness (p,))."""
    return [*_gradients(side, r, w), *_coefficients(side, r, w, params, energy_right)]


def stress_side_findings(
    model, points, cells, x, f, K, f_o, K_o, s: Scales, tol: Tolerances, energy_right: bool
):
    """The readings that bring the engine's f (n, 3), K within ``tol`` of the oracle's f_o, K_o
    plus their prediction (ambiguous when several predict differently); None when the pieces
    cannot be built.
    """
    side = stress_side(model, points, cells, x, f_o, K_o)
    if side is None:
        return None
    f_o, pat = np.asarray(f_o, dtype=np.float64), side.pattern
    r, w, off = residual(pat, f, K, f_o, K_o, s)
    params = scalar_parameters(model)
    kept = explaining(
        stress_candidates(side, r, w, params, energy_right), r, w, off, 3 * pat.n, tol
    )
    source = "this stress-side prediction (from mjed's declared terms, which add up to the oracle)"
    return ambiguous([part_finding(c, d, f, K, f_o, K_o, pat, s, source) for c, d in kept])


def stress_side_reading(diag: Any, ci: Any, out: Any, ref: Any, s: Scales) -> Any:
    """``diag`` with a stress-side reading named first when one explains the engine."""
    e = diag.errors.energy
    energy_right = e is not None and e <= diag.tolerances.energy
    case = (ci.points, ci.cells, ci.positions, out.force, out.stiffness, ref.force, ref.stiffness)
    found = stress_side_findings(ci.model, *case, s, diag.tolerances, energy_right)
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
