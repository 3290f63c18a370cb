"""Reference finite-element codes that MJED is checked against.

The main one is the UFL Galerkin oracle, :class:`UFLOracle`: each strain energy is written
from its formula in UFL (:func:`strain_energy_density`) and differentiated by UFL, then
assembled by dolfinx. dolfinx and UFL are imported only when those names are first used, so
``import reference_fem`` works on machines without them; :func:`dolfinx_available` tells.
"""

from __future__ import annotations

from typing import Any

__all__ = ["UFLOracle", "strain_energy_density", "dolfinx_available"]

_available = None


def dolfinx_available() -> bool:
    """True if dolfinx (with UFL, PETSc and MPI) can be imported. The answer is cached."""
    global _available
    if _available is None:
        try:
            from reference_fem.compat import import_dolfinx

            import_dolfinx()  # dolfinx with its PETSc layer, whatever the release
            import ufl  # noqa: F401
        except Exception:  # ImportError, or a broken MPI/PETSc install failing on import
            _available = False
        else:
            _available = True
    return _available


def __getattr__(name: str) -> Any:
    # Lazy attributes (PEP 562): the heavy imports happen here, on first use.
    if name == "UFLOracle":
        from reference_fem.ufl_oracle import UFLOracle

        return UFLOracle
    if name == "strain_energy_density":
        from reference_fem.energies import strain_energy_density

        return strain_energy_density
    raise AttributeError(f"module 'reference_fem' has no attribute {name!r}")
