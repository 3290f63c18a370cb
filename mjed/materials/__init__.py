"""Hyperelastic materials, one file each, each declared once.

A material's file holds its parameters (a frozen dataclass, validated on construction), its
MJED terms (``decomposition()``, see :mod:`mjed.terms`), its formula, its default
parameters, its energy written from the formula for the oracle and the form of its law for
the classical element, all in one :class:`mjed.materials.declaration.Declaration`. Every
registry of the suite (oracle, classical element, compiled kernels, command-line names,
exchange format, SOFA names, the docs table) is read from :func:`declarations`. The energies
(zero at rest) are listed in docs/conventions.md, "The materials".

Importing this package declares the built-in materials: every module of this folder other than
the machinery below is a material's file, found and imported here (no list to edit), and the
names in its ``__all__`` are this package's. :func:`declarations` gives them in their declared
``order``.
"""

import importlib
import pkgutil

from mjed.materials.base import Material
from mjed.materials.declaration import Declaration, declaration_of, declarations
from mjed.materials.sofa import from_sofa

#: The modules of this folder that are machinery, not a material.
MACHINERY = ("base", "classical_forms", "declaration", "sofa")

__all__ = ["Material", "Declaration", "declarations", "declaration_of", "from_sofa"]


def _declare_the_materials_of_this_folder() -> None:
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name in MACHINERY or info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        for name in module.__all__:
            globals()[name] = getattr(module, name)
            __all__.append(name)


_declare_the_materials_of_this_folder()
