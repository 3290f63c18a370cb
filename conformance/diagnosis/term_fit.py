"""The energy as a sum of terms, each coefficient fitted.

Every energy with a formula (a declared material, a user energy) is split into its additive terms
(:func:`conformance.diagnosis.energy_terms.split_terms`); the oracle gives each term's force
and stiffness, and the engine's are fitted as a combination of them:

    minimise  sum over cases  ||sum_t a_t f_t - f||^2 / s_f^2 + ||sum_t a_t K_t - K||^2 / s_K^2

(linear least squares; one case, or all failing cases of a model in a kit). The fit *agrees* when
the engine's force and stiffness are within the case's tolerance of the fitted combination on every
case fitted; then the terms whose coefficient is not 1 are named, with the factor, and read:

- a term missing (0), with the wrong sign (-1), doubled or halved (2, 1/2), a power of ten
  (a parameter in other units);
- a parameter's terms scaled together by the ratio of two parameters' values: one parameter used
  for the other; both ways: the two exchanged;
- a factor near 1 (a rounded constant or parameter), else the factor itself.

When two terms have the same force and stiffness on the cases fitted (at rest, the I1b and I2b
terms of Mooney-Rivlin), their coefficients cannot be told apart: the fit says so and names no
term (the cases of a kit at other states can).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elastic_conversions import matching_conversion, moduli_names

__all__ = ["TermCase", "TermFit", "term_labels", "fit_terms", "describe_fit", "factor_words"]

#: Singular value ratio below which a combination of terms is not identified by the cases.
_IDENTIFIED = 1e-7

#: Named factors (value, words).
_FACTORS = (
    (0.0, "missing (dropped)"),
    (-1.0, "with the wrong sign"),
    (2.0, "doubled (a factor 1/2 dropped, or the term counted twice)"),
    (0.5, "halved (a factor 2 missing, or 1/2 applied twice)"),
    (-2.0, "doubled and with the wrong sign"),
    (3.0, "tripled"),
    (1.0 / 3.0, "divided by 3"),
)


@dataclass(frozen=True)
class TermCase:
    """One case's system: the oracle's per-term forces (T of (n, 3)) and stiffnesses (T of
    (3n, 3n)); the engine's f, K; the error scales and the tolerances of the case; names: each
    term's formula as declared (:func:`conformance.diagnosis.energy_terms.term_names`; empty, or
    None for a term, where unknown).
    """

    forces: Sequence[np.ndarray]
    stiffnesses: Sequence[sp.spmatrix]
    f: np.ndarray
    K: sp.spmatrix
    force_scale: float
    stiffness_scale: float
    force_tol: float
    stiffness_tol: float
    names: Tuple[Optional[str], ...] = ()
    #: J the same in every cell (a homogeneous state): the J-only terms' forces and stiffnesses
    #: then span any change of U'(J) and U''(J) at that J, whatever its cause.
    one_j: bool = False
    #: that J where ``one_j`` (None otherwise): a factor that is a function of J is one number
    #: there (corroborate.extend_covered)
    j_value: Optional[float] = None


@dataclass(frozen=True)
class TermFit:
    """coefficients (T,); identified: False when some combination of terms is not determined by
    the cases (then ``coupled`` lists the terms in it); residuals: per case (force, stiffness)
    relative errors after the fit; agrees: every case within its tolerances.
    """

    coefficients: np.ndarray
    identified: bool
    coupled: Tuple[int, ...]
    residuals: Tuple[Tuple[float, float], ...]
    agrees: bool

    @property
    def residual(self) -> float:
        return max(max(r) for r in self.residuals) if self.residuals else float("inf")


def term_labels(model: Any) -> List[Tuple[str, ...]]:
    """The parameters read by each additive term of ``model``'s energy (plain UFL, no mesh):
    as many entries as terms, in the order the oracle's terms come.
    """
    from conformance.diagnosis.energy_terms import Spec, split_terms, symbolic, term_parameters

    W, entered, F = symbolic(model, Spec(), "symbol")
    return [term_parameters(t, entered) for t in split_terms(W, F)]


def _columns(case: TermCase) -> Tuple[np.ndarray, np.ndarray]:
    """(A (N, T), b (N,)): the scaled stacked force and stiffness entries of one case."""
    mats = [sp.csr_matrix(k) for k in case.stiffnesses] + [sp.csr_matrix(case.K)]
    pattern = sp.csr_matrix(sum(abs(m) for m in mats))
    r, c = pattern.nonzero()
    cols = []
    for fk, Kk in zip(case.forces, case.stiffnesses):
        Kv = np.asarray(sp.csr_matrix(Kk)[r, c]).ravel()
        cols.append(
            np.concatenate(
                [np.ravel(fk) / case.force_scale, Kv / case.stiffness_scale],
            )
        )
    Kv = np.asarray(sp.csr_matrix(case.K)[r, c]).ravel()
    b = np.concatenate([np.ravel(case.f) / case.force_scale, Kv / case.stiffness_scale])
    return np.column_stack(cols), b


def fit_terms(cases: Sequence[TermCase]) -> Optional[TermFit]:
    """The least-squares coefficients over ``cases`` (None when there are no terms)."""
    if not cases or not len(cases[0].forces):
        return None
    blocks = [_columns(c) for c in cases]
    A = np.vstack([a for a, _ in blocks])
    b = np.concatenate([v for _, v in blocks])
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1.0
    As = A / norms
    U, sv, Vt = np.linalg.svd(As, full_matrices=False)
    keep = sv > _IDENTIFIED * sv[0] if sv.size and sv[0] > 0 else np.zeros(sv.size, bool)
    y = (U[:, keep].T @ b) / sv[keep]
    a = (Vt[keep].T @ y) / norms
    identified = bool(np.all(keep))
    coupled: Tuple[int, ...] = ()
    if not identified:
        null = Vt[~keep]
        coupled = tuple(int(i) for i in np.flatnonzero(np.any(np.abs(null) > 1e-3, axis=0)))
    residuals = []
    agrees = True
    for c in cases:
        fr = sum(ai * fi for ai, fi in zip(a, c.forces)) - c.f
        Kr = sp.csr_matrix(sum(ai * sp.csr_matrix(Ki) for ai, Ki in zip(a, c.stiffnesses)) - c.K)
        ef = float(np.linalg.norm(fr)) / c.force_scale
        eK = float(np.sqrt(Kr.multiply(Kr).sum())) / c.stiffness_scale
        residuals.append((ef, eK))
        agrees = agrees and ef <= c.force_tol and eK <= c.stiffness_tol
    return TermFit(a, identified, coupled, tuple(residuals), bool(agrees))


def _label(i: int, labels: Sequence[Tuple[str, ...]], names: Sequence[Optional[str]] = ()) -> str:
    if i < len(names) and names[i]:
        return str(names[i])
    params = labels[i]
    same = [j for j, p in enumerate(labels) if p == params]
    name = f"the {' '.join(params)} term" if params else "a term without parameters"
    if len(same) > 1:
        name += f" ({same.index(i) + 1} of {len(same)})"
    return name


def factor_words(a: float, close: float) -> Optional[str]:
    for value, words in _FACTORS:
        if abs(a - value) <= close * max(1.0, abs(value)):
            return words
    if a > 0:
        k = np.log10(a)
        if abs(k - round(k)) < close and round(k) != 0:
            return f"scaled by 1e{int(round(k)):+d}: a parameter in other units (Pa, kPa, MPa?)"
    return None


#: multiples k of a parameter p tried for a factor e^(k p): the rest shift of an exponential's
#: argument (exp(p (X - 3)) = e^(-3 p) exp(p X)) lost (3), its sign flipped (6), halved...
_EXPONENTS = (1.0, 1.5, 2.0, 3.0, 6.0, 0.5)


def exponential_words(a: float, params: Dict[str, float], written: Sequence[str], close: float):
    """Words for a factor a = e^(k p) (k in +-_EXPONENTS, p a parameter that the terms' written
    formulas put inside an exponential), or None.
    """
    if a <= 0 or not any("exp(" in w for w in written):
        return None
    for p, v in params.items():
        if not v or not any(p in w.split("exp(", 1)[-1] for w in written):
            continue
        for k in _EXPONENTS:
            for sign in (1.0, -1.0):
                if abs(np.log(a) - sign * k * v) <= close:
                    said = ("" if sign > 0 else "-") + ("" if k == 1.0 else f"{k:g} ") + p
                    return (
                        f"scaled by {a:.6g} = e^({said}): a constant factor of the exponential "
                        f"written wrongly (exp({p} (X - 3)) is e^(-3 {p}) exp({p} X): that "
                        f"e^(-3 {p}) lost gives e^(3 {p}), written e^(+3 {p}) gives e^(6 {p}))"
                    )
    return None


def describe_fit(
    fit: TermFit,
    labels: Sequence[Tuple[str, ...]],
    params: Dict[str, float],
    close: float = 1e-6,
    names: Sequence[Optional[str]] = (),
) -> Tuple[str, List[str]]:
    """(one line: what differs, [one reading per deviating group]) for a fit that agrees.
    ``names``: each term's declared formula (a parameter's reading then says which terms).
    """
    a = fit.coefficients
    off = [i for i, ai in enumerate(a) if abs(ai - 1.0) > close]
    if not off:
        return "every term has coefficient 1", []
    readings: List[str] = []
    done: set = set()
    # One parameter's terms scaled together: group by parameter.
    groups: List[Tuple[str, List[int], float]] = []
    for p in params:
        terms = [i for i, lab in enumerate(labels) if p in lab]
        if not terms or any(i not in off for i in terms):
            continue
        if np.ptp(a[terms]) <= close * max(1.0, abs(a[terms[0]])):
            groups.append((p, terms, float(np.mean(a[terms]))))
    by_param = {p: (terms, v) for p, terms, v in groups}
    exchanged: set = set()
    for (p, (tp, ap)), (q, (tq, aq)) in itertools.combinations(by_param.items(), 2):
        vp, vq = params[p], params[q]
        if (
            vp
            and vq
            and abs(ap - vq / vp) <= close * abs(vq / vp)
            and abs(aq - vp / vq) <= close * abs(vp / vq)
        ):
            readings.append(
                f"parameters {p} and {q} exchanged: the terms of {p} scaled by {ap:.6g} = {q}/{p}, "
                f"those of {q} by {aq:.6g} = {p}/{q}"
            )
            exchanged |= {p, q}
            done |= set(tp) | set(tq)
    # Moduli changed as a conversion through (E, nu) with one slip would change them: the values
    # of every changed modulus predicted, so a match is the cause.
    moduli = moduli_names(params)
    scaled = {p: ap * params[p] for p, (_, ap) in by_param.items() if p in moduli}
    deviating = {p for p in moduli if any(p in labels[i] for i in off)}
    also: Dict[str, str] = {}
    if scaled and set(scaled) == deviating and not deviating & exchanged:
        for conv in matching_conversion(params, scaled, close=max(close, 1e-9)):
            (only,) = scaled if len(scaled) == 1 else (None,)
            if only is not None and factor_words(by_param[only][1], close):
                # one modulus off by a simple factor (mu doubled): as plain a story as the
                # conversion's, which cannot be told from it; both said, the plain one first
                also[only] = f"; or {conv.words}"
                break
            readings.append(conv.words)
            exchanged |= set(scaled)
            for p in scaled:
                done |= set(by_param[p][0])
            break
    for p, (tp, ap) in by_param.items():
        if p in exchanged or set(tp) <= done:
            continue
        vp = params[p]
        words = factor_words(ap, close)
        written = sorted({names[i] for i in tp if i < len(names) and names[i]})
        which = f" ({'; '.join(written)})" if written else ""
        other = [
            q
            for q, vq in params.items()
            if q != p and vp and abs(ap - vq / vp) <= close * abs(vq / vp)
        ]
        expo = exponential_words(ap, params, written, close)
        if expo and not other:
            readings.append(f"{'; '.join(written)}: {expo}")
        elif other:
            readings.append(
                f"{other[0]} used for {p}: the terms of {p} scaled by {ap:.6g} = "
                f"{other[0]}/{p}{which}"
            )
        elif words:
            readings.append(
                f"parameter {p}: its terms {words} (factor {ap:.6g}){which}{also.get(p, '')}"
            )
        elif abs(ap - 1.0) < 1e-3:
            readings.append(
                f"parameter {p} slightly off: its terms scaled by {ap:.9g} (relative "
                f"{ap - 1:+.2e}: a rounded constant or parameter?){which}"
            )
        else:
            readings.append(
                f"parameter {p}: its terms scaled by {ap:.6g} (as if {p} = {ap * vp:.6g}){which}"
            )
        done |= set(tp)
    for i in off:
        if i in done:
            continue
        written = [names[i]] if i < len(names) and names[i] else []
        words = factor_words(float(a[i]), close) or exponential_words(
            float(a[i]), params, written, close
        )
        if words is None and abs(a[i] - 1.0) < 1e-3:
            words = f"slightly off (relative {a[i] - 1:+.2e}: a rounded constant?)"
        readings.append(f"{_label(i, labels, names)} {words or 'scaled'} (coefficient {a[i]:.6g})")
    line = ", ".join(f"{_label(i, labels, names)} x {a[i]:.6g}" for i in off)
    return line, readings
