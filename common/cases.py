"""The materials and meshes of the studies, with the parameters used when none are given.

Parameters are liver-like soft-tissue values in SI units (Pa): shear moduli of a few kPa and
bulk moduli ten times larger, so the volumetric and isochoric parts both matter.
"""

from __future__ import annotations

from typing import Dict, Iterable, Tuple

from mjed import materials as M
from mjed.materials.base import Material

__all__ = ["DEFAULT_MATERIALS", "material_names", "default_material", "parse_materials"]

#: One representative parameter set per material, keyed by the material's name.
DEFAULT_MATERIALS: Dict[str, Material] = {
    m.name: m
    for m in (
        M.StVenantKirchhoff(mu=3448.2759, lam=31034.483),  # E = 1e4, nu = 0.45
        M.NeoHookean(mu=3448.2759, lam=31034.483),
        M.MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4),
        M.VerondaWestmann(c1=1500.0, c2=1.4, k0=3.0e4),
        M.ArrudaBoyce(mu=2500.0, k0=3.0e4),
        # Fibre stiffer than sheet and normal, with shear couplings (Guccione-like ratios).
        M.Costa(a=800.0, k0=3.0e4, b_ff=18.5, b_fs=2.8, b_ss=3.6, b_fn=2.0, b_sn=1.6, b_nn=3.6),
        M.Ogden(mu=5000.0, alpha=3.0, k0=3.0e4),
    )
}

_ALIASES = {n.lower(): n for n in DEFAULT_MATERIALS}
_ALIASES.update(
    {
        "stvk": "StVenantKirchhoff",
        "svk": "StVenantKirchhoff",
        "nh": "NeoHookean",
        "mr": "MooneyRivlin",
        "vw": "VerondaWestmann",
        "verondawestman": "VerondaWestmann",
        "ab": "ArrudaBoyce",
    }
)


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
