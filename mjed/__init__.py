"""mjed: Multiplicative Jacobian Energy Decomposition for P1 tetrahedra, in NumPy.

    >>> import mjed
    >>> mesh = mjed.TetMesh(points, cells)
    >>> field = mjed.HyperelasticForceField(mesh, mjed.materials.NeoHookean(mu=1e3, lam=1e4))
    >>> f, K = field.force_and_stiffness(x)

This package depends on NumPy and SciPy only; it never imports dolfinx, UFL or PETSc.
"""

from mjed import materials
from mjed.backends import make_force_field
from mjed.darcy import DarcyParameters, FluidPressureForce
from mjed.errors import IntegrationError, InvertedElementError, MeshError, MeshWarning
from mjed.forcefield import HyperelasticForceField
from mjed.integrator import ImplicitEuler, Prescribed, StepReport
from mjed.mesh import TetMesh
from mjed.porous import PorousVolume, with_porous_volume
from mjed.viscous import Prony, ViscoHyperelasticForceField

__all__ = [
    "TetMesh",
    "HyperelasticForceField",
    "make_force_field",
    "MeshError",
    "MeshWarning",
    "InvertedElementError",
    "materials",
    "ImplicitEuler",
    "Prescribed",
    "StepReport",
    "IntegrationError",
    "Prony",
    "ViscoHyperelasticForceField",
    "PorousVolume",
    "with_porous_volume",
    "DarcyParameters",
    "FluidPressureForce",
]
__version__ = "0.1.0"
