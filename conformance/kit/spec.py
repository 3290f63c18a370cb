"""What an engine is asked to compute: a model (material or user energy) on a mesh at a state.

A *model* is either one of the declared materials of :mod:`mjed.materials` (its name and
numeric parameters, plus a Costa fibre frame) or a user energy
(:class:`reference_fem.user_energy.UserEnergy`: expression, parameters, optional fibre or
frame).
:func:`model_to_manifest` and :func:`model_from_manifest` turn one into the ``"model"`` entry of
the exchange format and back (docs/conventions.md, "Exchange format").
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

from mjed.materials import declarations
from mjed.materials.base import Material

__all__ = [
    "CaseInput",
    "MATERIAL_TYPES",
    "model_to_manifest",
    "model_from_manifest",
    "model_label",
    "model_frame",
    "SpecError",
]

#: The declared materials, by the name written in a manifest (deserialisation registry).
MATERIAL_TYPES: Dict[str, type] = {d.name: d.material for d in declarations()}


class SpecError(ValueError):
    """A model entry that cannot be read (unknown material, bad parameter)."""


@dataclass(frozen=True)
class CaseInput:
    """One evaluation an engine is asked for.

    case_id: unique name, e.g. "NeoHookean.cube-small.uniaxial" (probes: "...~probe2").
    points: (n, 3) float64 rest positions X [m]; cells: (m, 4) int64 node indices (0-based).
    positions: (n, 3) float64 current positions x [m].
    model: an mjed material or a user energy.
    """

    case_id: str
    points: np.ndarray
    cells: np.ndarray
    positions: np.ndarray
    model: Any

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=np.float64)
        cells = np.asarray(self.cells, dtype=np.int64)
        x = np.asarray(self.positions, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or x.shape != pts.shape:
            raise ValueError(
                f"case {self.case_id}: points {pts.shape} and positions {x.shape} must both be (n, "
                "3)"
            )
        if cells.ndim != 2 or cells.shape[1] != 4:
            raise ValueError(f"case {self.case_id}: cells must be (m, 4), got {cells.shape}")
        for name, arr in (("points", pts), ("cells", cells), ("positions", x)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_nodes(self) -> int:
        return self.points.shape[0]

    @property
    def n_cells(self) -> int:
        return self.cells.shape[0]


def _user_energy_type() -> Optional[type]:
    try:
        from reference_fem.user_energy import UserEnergy
    except ImportError:  # the parser is optional until it lands; materials still work
        return None
    return UserEnergy


@functools.singledispatch
def model_to_manifest(model: Any) -> Dict[str, Any]:
    """The JSON entry of a model (arrays such as a per-cell frame are returned separately by
    :func:`model_frame`). Raises TypeError for an object that is not a model.
    """
    UE = _user_energy_type()
    if UE is not None and isinstance(model, UE):
        fibre = None if model.fibre is None else [float(v) for v in model.fibre]
        return {
            "kind": "energy",
            "name": str(model.name),
            "expression": str(model.expression),
            "parameters": {str(k): float(v) for k, v in dict(model.params).items()},
            "fibre": fibre,
        }
    raise TypeError(
        f"not a model: {type(model).__name__} (expected an mjed material or a UserEnergy)"
    )


@model_to_manifest.register
def _(model: Material) -> Dict[str, Any]:
    params = {
        f.name: float(getattr(model, f.name))
        for f in dataclasses.fields(model)
        if isinstance(getattr(model, f.name), (int, float))
        and not isinstance(getattr(model, f.name), bool)
    }
    return {"kind": "material", "name": type(model).__name__, "parameters": params}


def model_frame(model: Any) -> Optional[np.ndarray]:
    """The fibre frame (3, 3) or (m, 3, 3) (columns fibre, sheet, normal) of Costa or of a user
    energy with I4/I5, else None.
    """
    UE = _user_energy_type()
    has_frame = isinstance(model, Material) or (UE is not None and isinstance(model, UE))
    frame = getattr(model, "frame", None) if has_frame else None
    return None if frame is None else np.asarray(frame, dtype=np.float64)


def model_label(model: Any) -> str:
    """Short name for tables: the material's class name or the user energy's name."""
    entry = model_to_manifest(model)
    return entry["name"]


def _parameters(entry: Mapping[str, Any], where: str) -> Dict[str, float]:
    params = entry.get("parameters")
    if not isinstance(params, Mapping):
        raise SpecError(f"{where}: model.parameters must be an object of name: number")
    out = {}
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise SpecError(f"{where}: parameter {k} must be a finite number, got {v!r}")
        out[str(k)] = float(v)
    return out


def model_from_manifest(
    entry: Mapping[str, Any], frame: Optional[np.ndarray] = None, *, where: str = "manifest"
) -> Any:
    """Rebuild the model of a manifest entry; ``where`` names the file in error messages.

    Raises:
        SpecError: unknown kind or material, a missing, extra or invalid parameter.
    """
    if not isinstance(entry, Mapping):
        raise SpecError(f"{where}: 'model' must be an object")
    kind = entry.get("kind")
    params = _parameters(entry, where)
    if kind == "material":
        cls = MATERIAL_TYPES.get(entry.get("name"))
        if cls is None:
            raise SpecError(
                f"{where}: unknown material {entry.get('name')!r}; known: "
                f"{', '.join(MATERIAL_TYPES)}"
            )
        kwargs: Dict[str, Any] = dict(params)
        if frame is not None:
            kwargs["frame"] = frame
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise SpecError(f"{where}: {exc}") from None
    if kind == "energy":
        UE = _user_energy_type()
        if UE is None:
            raise SpecError(
                f"{where}: user energies need reference_fem.user_energy, which is not installed"
            )
        fibre = entry.get("fibre")
        try:
            return UE(
                expression=str(entry.get("expression")),
                params=params,
                fibre=None if fibre is None else tuple(float(v) for v in fibre),
                name=str(entry.get("name", "energy")),
                frame=frame,
            )
        except (TypeError, ValueError) as exc:
            raise SpecError(f"{where}: {exc}") from None
    raise SpecError(f"{where}: model.kind must be 'material' or 'energy', not {kind!r}")


def parameters_tuple(model: Any) -> Tuple[Tuple[str, float], ...]:
    """The numeric parameters of a model as (name, value) pairs, for text files."""
    return tuple(model_to_manifest(model)["parameters"].items())
