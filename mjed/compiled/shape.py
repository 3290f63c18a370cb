"""The structure of a lowered term table: what a specialised kernel is generated from.

A :class:`KernelShape` holds everything about a material's terms that changes the *code* of
its kernel (which kinds of f(J) and g(C), in which groups, which tangent slots, which
matrices vary per cell) and nothing that only changes *numbers* (moduli, exponents of J,
fibre weights, frames): those stay in the table's arrays and are read by the kernel at run
time. Two materials with the same shape therefore share one compiled kernel, and two
materials with different shapes can never share one (the shape names the generated source,
see :mod:`mjed.compiled.specialise`).

Three parameter values count as structure, because each changes which derivatives vanish
or how a power is formed: a J-power with exponent 0 is the constant 1 (f' = f'' = 0); the
integer exponent n of I1^n (n = 1 has no tangent pair; I1^n is formed by products); and the
tangent mode of an eigenvalue power sum (exact or SOFA's coaxial approximation).

Pure Python; no Numba.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Tuple

from mjed.compiled.lowering import G_KINDS, GROUP_KINDS, J_KINDS, SLOT_KINDS, TermTable
from mjed.fibre import FibreQuadratic
from mjed.spectral import EigenPowerSum
from mjed.terms import (
    GreenLagrangeQuadratic,
    I1Power,
    JLogJ,
    JPower,
    LinearI2,
    LogPolynomial,
    Unity,
)

__all__ = ["TermShape", "KernelShape", "kernel_shape"]

_J_NAMES = {J_KINDS[JPower]: "power", J_KINDS[LogPolynomial]: "logpoly", J_KINDS[JLogJ]: "jlogj"}
_G_NAMES = {
    G_KINDS[Unity]: "unity",
    G_KINDS[I1Power]: "i1power",
    G_KINDS[LinearI2]: "linear_i2",
    G_KINDS[GreenLagrangeQuadratic]: "green_lagrange",
    G_KINDS[FibreQuadratic]: "fibre",
    G_KINDS[EigenPowerSum]: "eigen",
}
_SLOT_NAMES = {code: name for name, code in SLOT_KINDS.items()}
_GROUP_NAMES = {0: "plain", **{code: cls.__name__.lower() for cls, code in GROUP_KINDS.items()}}


@dataclass(frozen=True)
class TermShape:
    """One term f(J) g(C): j in {"one", "power", "logpoly", "jlogj"}; g in {"unity",
    "i1power", "linear_i2", "green_lagrange", "fibre", "eigen"}; n the exponent of I1^n (0
    for other g); coaxial: the eigen tangent is SOFA's approximation; slots: the slot of each
    tangent pair, in the order of the invariant function's declaration.
    """

    j: str
    g: str
    n: int
    coaxial: bool
    slots: Tuple[int, ...]


@dataclass(frozen=True)
class KernelShape:
    """terms; groups as (first term, end term, function), function in {"plain", "exp", "log",
    "power"} (its shift and exponent are numbers, not structure); slots as (kind, identity),
    kind in {"first", "second", "spectral"}; per_cell_M / per_cell_R: the slot matrices /
    fibre frames are one per cell.
    """

    terms: Tuple[TermShape, ...]
    groups: Tuple[Tuple[int, int, str], ...]
    slots: Tuple[Tuple[str, bool], ...]
    per_cell_M: bool
    per_cell_R: bool

    @property
    def need_eig(self) -> bool:
        return any(t.g == "eigen" for t in self.terms)


def kernel_shape(table: TermTable) -> KernelShape:
    """The shape of ``table`` (see the module docstring for what counts as structure)."""
    terms = []
    for t in range(len(table.jkind)):
        j = _J_NAMES[int(table.jkind[t])]
        if j == "power" and table.jpar[t, 0] == 0.0:
            j = "one"
        g = _G_NAMES[int(table.gkind[t])]
        n = 0
        if g == "i1power":
            n = int(table.gpar[t, 1])
            if n != table.gpar[t, 1] or n < 1:
                raise NotImplementedError(
                    f"I1Power with exponent {table.gpar[t, 1]!r}: the compiled kernel needs an "
                    "integer n >= 1"
                )
        coaxial = g == "eigen" and table.gpar[t, 2] == 1.0
        slots = tuple(int(s) for s in table.tslot[t, : int(table.npair[t])])
        terms.append(TermShape(j, g, n, bool(coaxial), slots))
    starts = [int(s) for s in table.group_start]
    groups = tuple(
        (starts[i], starts[i + 1], _GROUP_NAMES[int(table.group_kind[i])])
        for i in range(len(starts) - 1)
    )
    slots = tuple((_SLOT_NAMES[int(k)], bool(i)) for k, i in zip(table.slot_kind, table.slot_ident))
    return KernelShape(
        tuple(terms), groups, slots, table.slot_M.shape[1] > 1, table.gmat.shape[1] > 1
    )
