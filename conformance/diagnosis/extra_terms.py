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
    """(parameter, "q p") with c = q p, q a simple fraction (denominator and numerator at most
    12), for the first parameter that gives one; None if none does.
    """
    for name, v in params.items():
        if not v or not np.isfinite(v):
            continue
        q = simple_fraction(c / v, 12, 1e-9)
        if q is None or q == 0 or abs(q.numerator) > 12:
            continue
        said = name if q == 1 else f"-{name}" if q == -1 else f"{q} {name}"
        return name, said
    return None


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
) -> List[Tuple[str, Dict[str, Any], np.ndarray, sp.csr_matrix]]:
    """(title, figures, predicted force (n, 3), stiffness (3n, 3n)) of each library term whose
    fitted multiple, added to the oracle's force f_o and stiffness K_o, gives the engine's f, K
    within ``tol`` with a coefficient that is a simple multiple of a parameter.
    """
    import mjed

    mesh = mjed.TetMesh(points, cells)
    K, K_o = sp.csr_matrix(K), sp.csr_matrix(K_o)
    df = (np.asarray(f, dtype=float) - f_o).ravel() / s.force
    dK = (K - K_o) / s.stiffness
    found = []
    for words, groups in library():
        try:
            f_t, K_t = mjed.HyperelasticForceField(mesh, _material(groups)).force_and_stiffness(x)
        except ValueError:  # a library term undefined at this state
            continue
        K_t = sp.csr_matrix(K_t)
        a, b = f_t.ravel() / s.force, K_t / s.stiffness
        norm = float(a @ a) + float(b.multiply(b).sum())
        if norm == 0.0:
            continue
        c = (float(a @ df) + float(b.multiply(dK).sum())) / norm
        said = _coefficient_words(c, params)
        if said is None:
            continue
        f_p, K_p = f_o + c * f_t, (K_o + c * K_t).tocsr()
        e = errors(f, K, None, f_p, K_p, 0.0, s)
        if not tol.within(e, energy=False):
            continue
        title = (
            f"your energy has one term more than the oracle's: {said[1]} {words} (a coefficient "
            f"of {words.split(' = ')[0]} written wrongly where the energy is expanded in "
            "invariants, or a term added or left out)"
        )
        found.append(
            (
                title,
                {"term": words, "coefficient": c, "parameter": said[0], "said": said[1]},
                f_p,
                K_p,
            )
        )
    return found
