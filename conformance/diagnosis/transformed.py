"""A model's energy evaluated as a :class:`~conformance.diagnosis.energy_terms.Spec` says (one
term, a kinematic mistake, factors of the powers of J): a material the oracle can take.

Its UFL energy is registered with :mod:`reference_fem.energies` when the first one is made, so
the oracle differentiates it as it does a model's own energy. A spec that differs from the
model only in numbers goes through :mod:`conformance.diagnosis.shared_form` (one compiled form
for all of them); the others through :func:`conformance.diagnosis.energy_terms.build`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from conformance.diagnosis import shared_form
from conformance.diagnosis.energy_terms import Spec, build

__all__ = ["TransformedEnergy"]


@dataclass(frozen=True, eq=False)
class TransformedEnergy:
    """``model``'s energy evaluated as ``spec`` says: a material for the oracle."""

    model: Any
    spec: Spec

    def __post_init__(self):
        # Registered with the oracle when first needed, not when this module is imported:
        # the oracle's formulas need UFL, and the kit tools that import the diagnosis (export,
        # the adapters, kit agreement) run on machines without it (a GPU machine, say).
        _register()

    @property
    def frame(self):
        return getattr(self.model, "frame", None)


def _register() -> None:
    from reference_fem.energies import register_energy, supported_materials

    if TransformedEnergy in supported_materials():
        return

    @register_energy(TransformedEnergy, takes_frame=True)
    def _energy(p, F, frame):
        spec = p.material.spec
        if p.constant is not None and shared_form.applies(spec):
            # one compiled form for every variant that differs only in numbers
            return shared_form.energy(p.material.model, F, frame, p.constant, spec)
        W, _ = build(p.material.model, F, frame, p.constant, spec)
        return W
