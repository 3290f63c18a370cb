"""One energy term too many (or too few): the engine's force and stiffness are the oracle's plus
those of one simple invariant term, ``c X``, with ``c`` a simple multiple of a parameter.

An energy expanded into invariants by hand goes wrong one coefficient at a time: St
Venant-Kirchhoff's ``mu tr(E^2)`` written with ``tr(C^2) = I1^2 - I2`` (for ``I1^2 - 2 I2``)
leaves ``mu/4 I2`` over; a Mooney-Rivlin engine with a term left out lacks ``c2 (I2b - 3)``. The
difference is then one term of a small library (I1, I1^2, I2 and their isochoric forms, ln J,
(ln J)^2, J, J^2), whatever the code looked like. Each library term's force and stiffness come
from mjed (plain NumPy, nothing compiled; mjed is held to the oracle term by term elsewhere), and
the one coefficient is fitted by least squares; it is named only when the fit brings the engine
within tolerance and the coefficient is a simple fraction of one parameter.
"""

from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.fractions import simple_fraction
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["library", "extra_terms"]


def library() -> Tuple[Tuple[str, Tuple[Any, ...]], ...]:
    """(the term in words, mjed's term groups of W = that term) for each library term."""
    from mjed.terms import I1Power, JPower, LinearI2, LogPolynomial, Term, TermGroup, Unity

    def one(f, g):
        return (TermGroup((Term(f, g),)),)

    return (
        ("I1", one(JPower(0.0), I1Power(1.0, 1))),
        ("I1^2", one(JPower(0.0), I1Power(1.0, 2))),
        ("I2", one(JPower(0.0), LinearI2(1.0))),
        ("I1b = J^(-2/3) I1", one(JPower(-2.0 / 3.0), I1Power(1.0, 1))),
        ("I1b^2 = J^(-4/3) I1^2", one(JPower(-4.0 / 3.0), I1Power(1.0, 2))),
        ("I2b = J^(-4/3) I2", one(JPower(-4.0 / 3.0), LinearI2(1.0))),
        ("ln J", one(LogPolynomial(0.0, 1.0), Unity())),
        ("(ln J)^2", one(LogPolynomial(1.0), Unity())),
        ("J", one(JPower(1.0), Unity())),
        ("J^2", one(JPower(2.0), Unity())),
    )


def _material(groups: Tuple[Any, ...]) -> Any:
    """An mjed material given by its term groups."""
    from mjed.materials.base import Material

    class LibraryTerm(Material):
        def decomposition(self):
            return groups

    return LibraryTerm()


def _coefficient_words(c: float, params: Dict[str, float]) -> Optional[Tuple[str, str]]:
    """(parameter(s), "q p") with c = q p, q a simple fraction (denominator and numerator at
    most 12) of one parameter or of a product of two (a coefficient such as Veronda-Westmann's
    c1 c2 / 2), the simplest fraction (the smallest numerator plus denominator; one parameter
    before a product at equal) of all that give one; None if none does.
    """
    values = {k: v for k, v in params.items() if v and np.isfinite(v)}
    products = [(name, v) for name, v in values.items()]
    names = list(values)
    products += [
        (f"{a} {b}", values[a] * values[b]) for i, a in enumerate(names) for b in names[i + 1 :]
    ]
    found = []
    for rank, (name, v) in enumerate(products):
        q = simple_fraction(c / v, 12, 1e-9)
        if q is None or q == 0 or abs(q.numerator) > 12:
            continue
        said = name if q == 1 else f"-{name}" if q == -1 else f"{q} {name}"
        found.append((abs(q.numerator) + q.denominator, rank, name, said))
    return min(found)[2:] if found else None


def _symbol(words: str) -> str:
    """A library term's symbol: "I1b" of "I1b = J^(-2/3) I1"."""
    return words.split(" = ")[0]


def extra_terms(
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    K: Any,
    f_o: np.ndarray,
    K_o: Any,
    s: Scales,
    tol: Tolerances,
    params: Dict[str, float],
    formula: str = "",
) -> List[Tuple[str, Dict[str, Any], np.ndarray, sp.csr_matrix]]:
    """(title, figures, predicted force (n, 3), stiffness (3n, 3n)) of each library term whose
    fitted multiple, added to the oracle's force f_o and stiffness K_o, gives the engine's f, K
    within ``tol`` with a coefficient that is a simple multiple of a parameter; when none does,
    of each pair of library terms, one for the other with one such coefficient (an invariant
    typed for another in a linear term: c (X - Y) over). formula: the oracle's energy as text,
    which says which of a pair's terms is the oracle's where only one of them appears in it.
    """
    import mjed

    mesh = mjed.TetMesh(points, cells)
    K, K_o = sp.csr_matrix(K), sp.csr_matrix(K_o)
    df = (np.asarray(f, dtype=float) - f_o).ravel() / s.force
    dK = (K - K_o) / s.stiffness
    terms = []
    for words, groups in library():
        try:
            f_t, K_t = mjed.HyperelasticForceField(mesh, _material(groups)).force_and_stiffness(x)
        except ValueError:  # a library term undefined at this state
            continue
        terms.append((words, f_t, sp.csr_matrix(K_t)))

    def fitted(f_t, K_t):
        """(c, its words, predicted f, K) of the one-coefficient fit of f_t, K_t, or None."""
        a, b = f_t.ravel() / s.force, K_t / s.stiffness
        norm = float(a @ a) + float(b.multiply(b).sum())
        if norm == 0.0:
            return None
        c = (float(a @ df) + float(b.multiply(dK).sum())) / norm
        said = _coefficient_words(c, params)
        if said is None:
            return None
        f_p, K_p = f_o + c * f_t, (K_o + c * K_t).tocsr()
        if not tol.within(errors(f, K, None, f_p, K_p, 0.0, s), energy=False):
            return None
        return c, said, f_p, K_p

    found = []
    for words, f_t, K_t in terms:
        fit = fitted(f_t, K_t)
        if fit is None:
            continue
        c, said, f_p, K_p = fit
        title = (
            f"your energy has one term more than the oracle's: {said[1]} {words} (a coefficient "
            f"of {_symbol(words)} written wrongly where the energy is expanded in invariants, "
            "or a term added or left out)"
        )
        figs = {"term": words, "coefficient": c, "parameter": said[0], "said": said[1]}
        found.append((title, figs, f_p, K_p))
    if found:
        return found
    for i, (wa, fa, Ka) in enumerate(terms):
        for wb, fb, Kb in terms[i + 1 :]:
            fit = fitted(fa - fb, (Ka - Kb).tocsr())
            if fit is None:
                continue
            c, said, f_p, K_p = fit
            title = _swapped_words(wa, wb, c, params, formula)
            figs = {
                "term": f"{_symbol(wa)} - {_symbol(wb)}",
                "coefficient": c,
                "parameter": said[0],
                "said": said[1],
            }
            found.append((title, figs, f_p, K_p))
    return found


def _swapped_words(wa: str, wb: str, c: float, params: Dict[str, float], formula: str) -> str:
    """The engine's energy is the oracle's plus c (a - b): the term of b written with a (c's
    sign as found), or the term of a written with b (-c); the one whose symbol the oracle's
    formula lacks is not the oracle's term, so only the other reading is said when one is.
    """
    a, b = _symbol(wa), _symbol(wb)
    has = {y: re.search(rf"\b{re.escape(y)}\b", formula) is not None for y in (a, b)}
    one = has[a] != has[b]  # the formula has one of them: that one is the oracle's term
    readings = []
    for new, old, k in ((a, b, c), (b, a, -c)):
        if one and not has[old]:
            continue
        said = _coefficient_words(k, params)
        readings.append(
            f"a term {said[1] if said else f'{k:.6g}'} {old} of the energy written with {new} "
            f"where {old} belongs"
        )
    return (
        f"one invariant typed for another in a linear term: your energy is the oracle's plus "
        f"{_coefficient_words(c, params)[1]} ({a} - {b}): " + ", or ".join(readings)
    )
