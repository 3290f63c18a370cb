"""The strain energy the oracle differentiates: W(F) per unit rest volume, written in UFL.

One function for both oracles of the checker (the full UFL oracle and the stiffness parts), so
that a built-in material and a user energy reach UFL the same way.
"""

from __future__ import annotations

from typing import Any, Callable, Optional

__all__ = ["energy_density"]


def energy_density(model: Any, F, frame=None, constant: Optional[Callable[[Any], Any]] = None):
    """W(F) per unit rest volume in UFL, for a built-in material or a user energy."""
    from conformance.kit.spec import _user_energy_type

    UE = _user_energy_type()
    if UE is not None and isinstance(model, UE):
        return model.ufl_density(F, constant=constant)
    from reference_fem.energies import strain_energy_density

    return strain_energy_density(model, F, frame=frame, constant=constant)
