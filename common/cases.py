"""The materials and meshes of the studies, with the parameters used when none are given.

Parameters are liver-like soft-tissue values in SI units (Pa): shear moduli of a few kPa and
bulk moduli ten times larger, so the volumetric and isochoric parts both matter.
"""

from __future__ import annotations

from typing import Dict, Iterable, Tuple

from mjed.materials import declarations
from mjed.materials.base import Material

__all__ = ["DEFAULT_MATERIALS", "material_names", "default_material", "parse_materials"]

#: One representative parameter set per material, keyed by the material's name: each
#: material's declared default (mjed/materials/<material>.py), in declaration order.
DEFAULT_MATERIALS: Dict[str, Material] = {d.name: d.default for d in declarations()}

#: Accepted spellings: the name in lower case, and the aliases each material declares.
_ALIASES = {d.name.lower(): d.name for d in declarations()}
_ALIASES.update({alias: d.name for d in declarations() for alias in d.aliases})


def material_names() -> Tuple[str, ...]:
    return tuple(DEFAULT_MATERIALS)


def default_material(name: str) -> Material:
    key = _ALIASES.get(name.lower().replace("-", "").replace("_", ""))
    if key is None:
        raise ValueError(
            f"unknown material {name!r}; known materials: {', '.join(DEFAULT_MATERIALS)} (or 'all')"
        )
    return DEFAULT_MATERIALS[key]


def parse_materials(spec: "str | Iterable[str]") -> Tuple[Material, ...]:
    """'all', one name, or a comma-separated list -> material instances."""
    names = spec.split(",") if isinstance(spec, str) else list(spec)
    names = [n.strip() for n in names if n.strip()]
    if not names:
        raise ValueError("no material given")
    if any(n.lower() == "all" for n in names):
        return tuple(DEFAULT_MATERIALS.values())
    return tuple(default_material(n) for n in names)
