"""A kit case's material as SOFA's ``materialName`` and ``ParameterSet``, per force field.

The parameter orders come from the material declarations (``Declaration.sofa``); this module
only adds what differs between SOFA's three hyperelastic force fields:

- ``mjed``: the SofaMJEDFEM plugin's ``MJEDTetrahedralForceField``; its Ogden reads
  ``[k0, mu, alpha]`` (the order SOFA used before its December 2025 Ogden rewrite);
- ``hyperelasticity``: SOFA's ``TetrahedronHyperelasticityFEMForceField``;
- ``standard``: SOFA's ``StandardTetrahedralFEMForceField``; both classical fields share SOFA's
  core material laws, whose Ogden reads ``[mu, alpha, k0]``.

What cannot be expressed is refused with the reason (:class:`NotExpressible`), never
approximated: materials SOFA does not have (Yeoh, Gent, user energies), and Costa with a
fibre frame other than the global axes (SOFA's Costa laws take the fibre, sheet and normal as
the x, y and z axes; none of the three fields reads a per-cell frame).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

__all__ = [
    "FORCEFIELDS",
    "NotExpressible",
    "SofaMaterial",
    "costa_in_global_axes",
    "sofa_material",
    "sofa_material_of",
]

#: The force fields the engine program drives, each with the SOFA class it instantiates.
FORCEFIELDS = {
    "mjed": "MJEDTetrahedralForceField (SofaMJEDFEM)",
    "hyperelasticity": "TetrahedronHyperelasticityFEMForceField",
    "standard": "StandardTetrahedralFEMForceField",
}

# The plugin kept SOFA's pre-2025 Ogden order; the core laws moved k0 last.
_OGDEN_ORDER = {"mjed": ("k0", "mu", "alpha"), "hyperelasticity": None, "standard": None}


class NotExpressible(ValueError):
    """The case's model has no counterpart in the chosen SOFA force field (the message says why)."""


@dataclass(frozen=True)
class SofaMaterial:
    """What the engine program passes to SOFA: ``materialName`` and ``ParameterSet``."""

    name: str
    parameters: Tuple[float, ...]

    def parameter_set(self) -> str:
        """The ParameterSet as SOFA reads it: values separated by spaces, round-trip exact."""
        return " ".join(repr(float(v)) for v in self.parameters)


def sofa_material(
    model: Mapping,
    forcefield: str,
    frame: Optional[np.ndarray] = None,
    as_material: Optional[str] = None,
) -> SofaMaterial:
    """The SOFA material for a case's ``model`` (case.json's ``model`` object).

    Args:
        model: ``{"kind": "material", "name": ..., "parameters": {...}}`` or a user energy.
        forcefield: a key of :data:`FORCEFIELDS`.
        frame: the case's per-cell frames ``(m, 3, 3)`` or one ``(3, 3)``, when it has one.
        as_material: for a user energy, the material it writes out (its parameters named as
            that material's): how a law SOFA evaluates in fixed axes, such as Costa in the
            global frame, is checked against the energy written in those axes.

    Raises:
        NotExpressible: a user energy, a material SOFA does not offer, or a Costa frame that
            is not the global axes.
        ValueError: an unknown force field, or a parameter missing from the model.
    """
    from mjed.materials.sofa import sofa_parameter_order

    if forcefield not in FORCEFIELDS:
        raise ValueError(f"unknown force field {forcefield!r}; one of {', '.join(FORCEFIELDS)}")
    if as_material is not None and model.get("kind") == "energy":
        model = {"kind": "material", "name": as_material, "parameters": model.get("parameters")}
    if model.get("kind") != "material":
        raise NotExpressible(
            "a user energy has no SOFA material: SOFA's force fields take only their own "
            "built-in laws (materialName)"
        )
    name = str(model.get("name"))
    by_class = {
        cls.__name__: (sofa_name, order)
        for sofa_name, (cls, order) in sofa_parameter_order().items()
    }
    if name not in by_class:
        offered = ", ".join(sorted(by_class))
        raise NotExpressible(f"SOFA has no {name} law (its laws map to: {offered})")
    sofa_name, order = by_class[name]
    if sofa_name == "Ogden" and _OGDEN_ORDER[forcefield] is not None:
        order = _OGDEN_ORDER[forcefield]
    if sofa_name == "Costa" and frame is not None and not _is_global_axes(frame):
        raise NotExpressible(
            "SOFA's Costa law takes the fibre, sheet and normal as the global x, y, z axes "
            "(it reads no frame), and this case has a per-cell fibre frame"
        )
    parameters = model.get("parameters", {})
    missing = [p for p in order if p not in parameters]
    if missing:
        raise ValueError(f"{name}: parameters {missing} missing from the case's model")
    return SofaMaterial(sofa_name, tuple(float(parameters[p]) for p in order))


def sofa_material_of(material: Any, forcefield: str) -> SofaMaterial:
    """:func:`sofa_material` for an mjed material object (its own frame, if it has one)."""
    model = {
        "kind": "material",
        "name": type(material).__name__,
        "parameters": {f.name: getattr(material, f.name) for f in fields(material)},
    }
    return sofa_material(model, forcefield, getattr(material, "frame", None))


def _is_global_axes(frame: np.ndarray) -> bool:
    frames = np.asarray(frame, dtype=float).reshape(-1, 3, 3)
    return bool(np.array_equal(frames, np.broadcast_to(np.eye(3), frames.shape)))


def costa_in_global_axes(parameters: Mapping[str, float]) -> Tuple[str, Dict[str, float]]:
    """Costa's energy written out in the global axes, as a user energy (expression, parameters).

    SOFA's Costa law has no frame: fibre, sheet and normal are x, y and z. Checked as this user
    energy (``--energy``), with the case read back as Costa by the adapter (``--as-material
    Costa``), SOFA's law meets the oracle on the same formula as the declaration's, with
    ``R = I``: ``Q = sum_ij B_ij E_ij^2`` counts each off-diagonal pair twice.
    """
    b = _costa_b_names()  # b_ff, b_fs, b_ss, b_fn, b_sn, b_nn: B's upper triangle by columns
    names = [[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]]
    terms = [f"{names[i][j]}*E{i + 1}{j + 1}**2" for i in range(3) for j in range(3)]
    q = " + ".join(terms)
    expression = f"a/2*(exp(J**(-4/3)*({q})) - 1) + k0*(J*ln(J) - J + 1)"
    return expression, {k: float(parameters[k]) for k in ("a", "k0") + _costa_b_names()}


def _costa_b_names() -> Tuple[str, ...]:
    """Costa's B parameters in SOFA's ParameterSet order, from its declaration."""
    from mjed.materials.sofa import sofa_parameter_order

    return tuple(sofa_parameter_order()["Costa"][1][2:])
