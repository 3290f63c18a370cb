"""SOFA's own hyperelastic force fields (the SofaMJEDFEM plugin's MJED and SOFA's two classical
fields) run as an engine of the exchange format; see ``python -m conformance.adapters.sofa``.
"""

from conformance.adapters.sofa.mapping import (
    FORCEFIELDS,
    NotExpressible,
    SofaMaterial,
    sofa_material,
)
from conformance.adapters.sofa.program import build, find_program, how_to_build

__all__ = [
    "FORCEFIELDS",
    "NotExpressible",
    "SofaMaterial",
    "build",
    "find_program",
    "how_to_build",
    "sofa_material",
]
