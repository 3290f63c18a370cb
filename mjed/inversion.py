"""Which materials may continue through inverted cells (J <= 0).

The paper's regularisation (section 2.3) makes the stiffness of compressed cells diagonal-like
and, in its words, "it is even possible to handle inverted elements when the strain energy
remains finite at J = 0". Whether it does is a property of the declared energy: every
function of J in its terms must give finite values (f, f', f'') at J = 0 and below. A power
J^p with p < 0 (the isochoric J^(-2/3) of Mooney-Rivlin, Arruda-Boyce, Veronda-Westmann,
Ogden; Costa's J^(-4/3)) is infinite at 0 and, for a non-integer p, undefined below; ln J
(Neo-Hookean, and the volumetric (ln J)^2 terms of most laws) and Costa's J ln J are undefined
for J <= 0. Of the declared materials of :mod:`mjed.materials`, only St Venant-Kirchhoff (no J
factor at all) qualifies; the porous solid's U(J) (:class:`mjed.porous.PorousVolume`, linear
below J0) qualifies as well.

The test is done on the declared terms themselves, at sample values of J, so a new material
is classified by what it declares, not by a list kept by hand.
"""

from __future__ import annotations

from typing import Iterable, List, Tuple

import numpy as np

from mjed.materials.base import Material
from mjed.terms import Log, Power

__all__ = ["finite_when_inverted", "inversion_blockers", "SAMPLE_J"]

#: Values of J <= 0 at which every function of J must stay finite.
SAMPLE_J = np.array([0.0, -1e-3, -0.5, -2.0])


def _j_functions(material: Material) -> Iterable:
    for group in material.decomposition():
        for term in group.terms:
            yield term.f


def inversion_blockers(material: Material) -> List[Tuple[str, str]]:
    """The functions of J of ``material`` that are not finite at some J <= 0.

    Returns: [(repr of the function, the first sample J where it fails)], empty when the
    material qualifies.
    """
    blockers = []
    for f in _j_functions(material):
        with np.errstate(all="ignore"):
            values = [
                np.broadcast_to(np.asarray(v, dtype=float), SAMPLE_J.shape)
                for v in f(SAMPLE_J.copy())
            ]
        finite = np.logical_and.reduce([np.isfinite(v) for v in values])
        if not finite.all():
            blockers.append((repr(f), f"J = {SAMPLE_J[np.flatnonzero(~finite)[0]]:g}"))
    for group in material.decomposition():
        fn = group.function
        # ln(a + u) and a non-integer power of (a + u) are undefined where a + u <= 0, which an
        # inverted cell can reach whatever its terms; e^u and integer powers are entire
        if isinstance(fn, Log) or (isinstance(fn, Power) and float(fn.p) != int(fn.p)):
            blockers.append((repr(fn), "a + u <= 0"))
    return blockers


def finite_when_inverted(material: Material) -> bool:
    """True when every term of the material's energy (and its first two J derivatives) is
    finite for J <= 0, so that inverted cells can be evaluated (with the regularisation).
    """
    return not inversion_blockers(material)
