"""Import of SOFA material declarations (materialName + ParameterSet).

SOFA's hyperelastic force fields take a material name and a flat list of reals whose order
depends on the material (:func:`sofa_parameter_order`, from the declarations). Ogden's order
changed in SOFA's December 2025 rewrite: [mu, alpha, k0] since then ("sofa"), [k0, mu, alpha]
in the MJED plugin and older SOFA ("mjed").
"""

from __future__ import annotations

from typing import Callable, Dict, Sequence, Tuple, Union

from mjed.materials.base import Material
from mjed.materials.declaration import declarations
from mjed.materials.ogden import Ogden

__all__ = ["from_sofa", "sofa_parameter_order"]


def sofa_parameter_order() -> Dict[str, Tuple[Callable[..., Material], Tuple[str, ...]]]:
    """SOFA material name -> (class, parameter names in ParameterSet order), read from the
    declarations when asked (so it holds every material declared by then, whatever the order
    in which their files were imported).
    """
    return {d.sofa[0]: (d.material, d.sofa[1]) for d in declarations() if d.sofa is not None}


_OGDEN_MJED_ORDER = ("k0", "mu", "alpha")
#: Other spellings accepted for a SOFA name.
_SOFA_ALIASES = {"VerondaWestmann": "VerondaWestman"}


def from_sofa(
    name: str, parameter_set: Union[str, Sequence[float]], ogden_order: str = "sofa"
) -> Material:
    """The material a SOFA scene declares.

    Args:
        name: SOFA's materialName, e.g. "ArrudaBoyce", "VerondaWestman" (SOFA's spelling;
            "VerondaWestmann" is accepted too).
        parameter_set: SOFA's ParameterSet, as its string ("3448.2759 31034.483") or numbers.
        ogden_order: "sofa" for [mu, alpha, k0] (SOFA >= 2025-12), "mjed" for [k0, mu, alpha]
            (the MJED plugin and older SOFA).

    Raises:
        ValueError: unknown name, wrong parameter count (the message lists the expected
            parameters), non-numeric values, or parameters the material refuses.
    """
    key = _SOFA_ALIASES.get(name, name)
    order_table = sofa_parameter_order()
    if key not in order_table:
        raise ValueError(f"unknown SOFA material {name!r}; supported: {', '.join(order_table)}")
    if ogden_order not in ("sofa", "mjed"):
        raise ValueError(f"ogden_order must be 'sofa' or 'mjed', got {ogden_order!r}")
    cls, order = order_table[key]
    if cls is Ogden and ogden_order == "mjed":
        order = _OGDEN_MJED_ORDER
    values = _parse(parameter_set, key)
    if len(values) != len(order):
        which = f" with ogden_order={ogden_order!r}" if cls is Ogden else ""
        raise ValueError(
            f"SOFA {key}{which} expects {len(order)} parameters [{', '.join(order)}], "
            f"got {len(values)}: {list(values)}"
        )
    return cls(**dict(zip(order, values)))


def _parse(parameter_set, name: str) -> Tuple[float, ...]:
    items = parameter_set.split() if isinstance(parameter_set, str) else list(parameter_set)
    try:
        return tuple(float(v) for v in items)
    except (TypeError, ValueError):
        raise ValueError(
            f"SOFA {name}: ParameterSet must hold numbers, got {parameter_set!r}"
        ) from None
