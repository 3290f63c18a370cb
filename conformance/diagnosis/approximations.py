"""Published tangent approximations: a stiffness that is a known approximation of the Hessian.

Some engines ship a tangent that is not the derivative of their force on purpose or by
inheritance, and a check then finds the force right and the stiffness off by a small, structured
amount. Where a material declares such approximations as options of its own (a dataclass field
``tangent`` whose other values name them, e.g. ``Ogden(tangent="sofa")``: SOFA's MJED plugin
differentiates ``C^p`` as ``p C^((p-1)/2) H C^((p-1)/2)``, exact only when the eigenvalues of
``C`` are equal), each is evaluated by the project's MJED engine at the case's positions and
compared with the engine's stiffness. The oracle stays the judge; this only names which known
tangent the engine computes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Iterator, List, Optional

import numpy as np
import scipy.sparse as sp

__all__ = ["TangentMatch", "APPROXIMATIONS", "match_approximation"]

#: tangent option -> what it is, in words an engine's author can look up.
APPROXIMATIONS = {
    "sofa": "the coaxial approximation of SOFA's MJED plugin (SofaMJEDFEM's OgdenMJED): "
    "d(C^p)[H] taken as p C^((p-1)/2) H C^((p-1)/2), exact only where C's eigenvalues are "
    "equal",
}


@dataclass(frozen=True)
class TangentMatch:
    """The engine's stiffness against one known approximation: ``error`` relative to it."""

    option: str
    words: str
    error: float


def _alternatives(model: Any) -> Iterator[Any]:
    if not dataclasses.is_dataclass(model):
        return
    names = {f.name for f in dataclasses.fields(model)}
    if "tangent" not in names:
        return
    for option in APPROXIMATIONS:
        if option != getattr(model, "tangent"):
            try:
                yield option, dataclasses.replace(model, tangent=option)
            except (TypeError, ValueError):  # the material does not offer this option
                continue


def match_approximation(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    positions: np.ndarray,
    stiffness: sp.spmatrix,
    tolerance: float,
) -> Optional[TangentMatch]:
    """The known approximation the engine's ``stiffness`` equals within ``tolerance`` (relative,
    Frobenius), or None. ``model`` is the case's material; nothing is tried for other models.
    """
    import mjed

    found: List[TangentMatch] = []
    for option, alternative in _alternatives(model):
        field = mjed.make_force_field(mjed.TetMesh(points, cells), alternative)
        K_alt = sp.csr_matrix(field.stiffness(positions))
        scale = sp.linalg.norm(K_alt)
        if scale == 0:
            continue
        error = float(sp.linalg.norm(sp.csr_matrix(stiffness) - K_alt) / scale)
        if error <= tolerance:
            found.append(TangentMatch(option, APPROXIMATIONS[option], error))
    return min(found, key=lambda m: m.error) if found else None
