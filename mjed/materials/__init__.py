"""Hyperelastic materials, one file each, each declared once.

A material's file holds its parameters (a frozen dataclass, validated on construction), its
MJED terms (``decomposition()``, see :mod:`mjed.terms`), its formula, its default
parameters, its energy written from the formula for the oracle and the form of its law for
the classical element, all in one :class:`mjed.materials.declaration.Declaration`. Every
registry of the suite (oracle, classical element, compiled kernels, command-line names,
exchange format, SOFA names, the docs table) is read from :func:`declarations`. The energies
(zero at rest) are listed in docs/conventions.md, "The materials".

Importing this package declares the built-in materials, in this order.
"""

# isort: off
# The import order is the declaration order: the order of the docs table, of --material all
# and of every table a study prints. Keep it by hand (isort would sort it by file name).
from mjed.materials.base import Material
from mjed.materials.st_venant_kirchhoff import StVenantKirchhoff
from mjed.materials.neo_hookean import NeoHookean
from mjed.materials.mooney_rivlin import MooneyRivlin
from mjed.materials.veronda_westmann import VerondaWestmann
from mjed.materials.arruda_boyce import ARRUDA_BOYCE_COEFFICIENTS, ArrudaBoyce
from mjed.materials.costa import Costa
from mjed.materials.ogden import Ogden
from mjed.materials.yeoh import Yeoh
from mjed.materials.gent import Gent
from mjed.materials.declaration import Declaration, declaration_of, declarations
from mjed.materials.sofa import from_sofa
# isort: on

__all__ = [
    "Material",
    "StVenantKirchhoff",
    "NeoHookean",
    "MooneyRivlin",
    "VerondaWestmann",
    "ArrudaBoyce",
    "Costa",
    "Ogden",
    "Yeoh",
    "Gent",
    "Declaration",
    "declarations",
    "declaration_of",
    "from_sofa",
    "ARRUDA_BOYCE_COEFFICIENTS",
]
