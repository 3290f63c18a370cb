"""An operation-count model of force + stiffness per element, for MJED and the classical
Galerkin, derived from a material's declared MJED terms and from its classical law.

What it is for: the timing study compares the compiled MJED kernel with the compiled
classical kernel (mjed/compiled/codegen.py, reference_fem/classical_kernels.py). If both are
limited by arithmetic, the ratio of their times should follow the ratio of the operations
they execute; where it does not, memory traffic, branches or call overheads are at work, and
the study says so.

Counting rules (one cell, one force+stiffness evaluation, counted from the loops of the
compiled kernels as they are written, at a generic state with distinct eigenvalues):

- one flop per floating-point add, subtract, multiply or divide, and per square root;
- a libm call (log, exp, pow, expm1, log1p) counts ``TRANSCENDENTAL`` = 20 flops, about its
  cost in multiply-adds on x86-64;
- comparisons, branches, integer index arithmetic, loads and stores count nothing (the
  bandwidth floor of comparisons/bandwidth.py is about memory);
- the 3x3 eigen-decomposition (Jacobi) counts ``JACOBI_SWEEPS`` = 4 sweeps of 3 rotations;
- assembly counts the additions into the per-edge and per-node sums; the ordered write of
  the CSR array is a copy and counts nothing.

MJED's count comes from the term list (mjed.terms types, via a registry keyed by type) and
the tangent slots the lowering builds from it (mjed/compiled/lowering.py), so a new material
is counted without touching this module unless it brings a new term type. The classical
count comes from a registry keyed by the classical law type.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Dict, Tuple

import numpy as np

from mjed.fibre import FibreQuadratic
from mjed.materials.base import Material
from mjed.spectral import EigenPowerSum
from mjed.terms import GreenLagrangeQuadratic, I1Power, JLogJ, JPower, LinearI2, LogPolynomial, Term, Unity

__all__ = ["TRANSCENDENTAL", "JACOBI_SWEEPS", "OpCount", "mjed_flops", "classical_flops", "model"]

TRANSCENDENTAL = 20
JACOBI_SWEEPS = 4
T = TRANSCENDENTAL
# One Jacobi rotation: theta, t, c, s (with two square roots) and three 3x3 row/column updates.
_ROTATION = 14 + 3 * 18
EIGEN = JACOBI_SWEEPS * (3 * _ROTATION + 6)
MATMUL3 = 45  # a 3x3 by 3x3 product
APPLY_4 = 60  # a 3x3 matrix applied to the four shape vectors


@dataclass(frozen=True)
class OpCount:
    """Flops per cell by part, and their total."""

    method: str
    parts: Dict[str, int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return int(sum(self.parts.values()))

    def to_dict(self) -> dict:
        return {"method": self.method, "parts": dict(self.parts), "total": self.total}


# ------------------------------------------------------------------ MJED: per term type
def _f_jpower(f: JPower) -> int:
    return 0 if f.p == 0.0 else T + 6


_F_COST: Dict[type, Callable] = {JPower: _f_jpower, LogPolynomial: lambda f: T + 12, JLogJ: lambda f: T + 8}

# (value + stress, tangent coefficients) of each invariant type.
_G_COST: Dict[type, Callable] = {
    Unity: lambda g: (0, 0),
    I1Power: lambda g: (3, 0) if g.n == 1 else (2 * T + 12, T + 5),
    LinearI2: lambda g: (1 + 9 * 3, 2),
    GreenLagrangeQuadratic: lambda g: (4 + 9 * 6 + 4, 1),
    FibreQuadratic: lambda g: (27 * 3 + 27 * 2 + 27 + 81 * 3, 0),
    # S from three powers; the exact tangent: three pair quotients, three diagonal limits, the scaling.
    EigenPowerSum: lambda g: (3 * T + 6 + 9 * 9, 3 * 8 + 3 * 2 + 18),
}


def _lookup(obj, table: Dict[type, Callable], what: str):
    for cls in type(obj).__mro__:
        if cls in table:
            return table[cls]
    raise NotImplementedError(f"no operation count for the {what} {type(obj).__name__}")


def _varies(f) -> bool:
    """Whether f(J) is not a constant (so f' and f'' terms exist)."""
    return not (isinstance(f, JPower) and f.p == 0.0)


def mjed_flops(material: Material) -> OpCount:
    """The model of the compiled MJED kernel for ``material`` (see the module's rules)."""
    from mjed.compiled.lowering import lower_groups

    groups = material.decomposition()
    table = lower_groups(groups, np.zeros((1, 4, 3)))
    terms: Tuple[Term, ...] = tuple(t for g in groups for t in g.terms)
    stressed = [not isinstance(t.g, Unity) for t in terms]
    has_S = any(stressed)
    has_Sh = any(s and _varies(t.f) for s, t in zip(stressed, terms))
    has_h = any(_varies(t.f) for t in terms)
    need_eig = table.need_eig
    n_exp = int(table.group_exp.sum())
    slots = list(zip(table.slot_kind.tolist(), table.slot_ident.tolist()))
    n_first = sum(1 for k, _ in slots if k == 0)
    n_second = sum(1 for k, _ in slots if k == 1)
    n_spectral = sum(1 for k, _ in slots if k == 2)
    n_plain_slots = n_first + n_second

    parts: Dict[str, int] = {}
    parts["kinematics"] = 72 + 27 + 5 + 45 + 2 + 18 + 3 + (EIGEN if need_eig else 0)
    term_cost = 0
    for t in terms:
        value, tangent = _lookup(t.g, _G_COST, "invariant function")(t.g)
        term_cost += _lookup(t.f, _F_COST, "function of J")(t.f) + value + tangent + 6
        term_cost += 36 if not isinstance(t.g, Unity) else 0
        term_cost += 2 * len(t.g.tangent) + (18 if isinstance(t.g, EigenPowerSum) else 0)
    groups_cost = len(groups) * (2 * 27 + 2 * n_plain_slots + 4) + n_exp * (T + 1 + MATMUL3 + 18 + APPLY_4)
    parts["terms"] = term_cost + groups_cost
    parts["force"] = APPLY_4 + MATMUL3 + 4 * 3 * 8
    per_cell = APPLY_4  # S D_a
    per_cell += (MATMUL3 + APPLY_4) if has_Sh else 0
    for kind, ident in slots:
        if kind == 2:
            per_cell += 45 + 60  # F v_n and v_n . D_a
            continue
        per_cell += 4 * 3 * (5 if ident else 10)
        per_cell += 9 * 9 * 3 if kind == 1 else 0  # F M F^T
    per_edge = 3 + (5 if has_S else 0) + 27 * n_first + 46 * n_second + 189 * n_spectral
    per_edge += 54 if (has_Sh or has_h) else 0
    per_edge += 27 * n_exp + (6 if has_h else 0)  # h d2J: (h / 6) (x_d - x_c), not h F (D_a x D_b)
    parts["edge blocks"] = per_cell + 6 * per_edge
    # edge sums; node blocks K_aa as upper triangles (three blocks summed) subtracted into Dg
    parts["assembly"] = 6 * 9 + 4 * 6 * 2 + 4 * 9
    return OpCount("mjed", parts)


# ------------------------------------------------------------------ classical: per law type
def _law_costs():
    from reference_fem import classical_materials as cm

    odot = 36 * 4
    volumetric = 36 * 5 + 6 * 3 + T + 10
    # ... the isochoric projection as two rank-one updates (w, w CCb, N66 w: 6 * 2 + 36 * 2 * 2 + 36 * 2)
    decoupled_core = 25 + T + 6 * 10 + 36 * 10 + 6 * 2 + 36 * 6 + 36 * 10 + odot + volumetric
    return {
        cm.StVenantKirchhoffLaw: lambda law: 20 + 6 * 5 + 36 * 3,
        cm.NeoHookeanLaw: lambda law: T + odot + 6 * 3 + 36 * 4 + 10,
        cm.MooneyRivlinLaw: lambda law: decoupled_core + 4,
        cm.VerondaWestmannLaw: lambda law: decoupled_core + T + 12,
        cm.ArrudaBoyceLaw: lambda law: decoupled_core + 5 * 3 * T + 30,
        # eigen, four powers, S, H, M (4H) M^T, three pair terms (two libm calls each), volumetric
        cm.OgdenLaw: lambda law: (EIGEN + 4 * T + 6 * 3 * 4 + 9 * 10 + 36 * 9 * 4 + 3 * (2 * T + 10 + 36 * 8)
                                  + odot + volumetric),
        cm.CostaLaw: lambda law: 36 * 2 + 12 + 2 * T + 20 + 6 * 4 + 36 * 14 + odot + T,
    }


def classical_flops(material: Material) -> OpCount:
    """The model of the compiled classical kernel for ``material``'s classical law."""
    from reference_fem.classical_materials import classical_law

    law = classical_law(material)
    costs = _law_costs()
    cost = costs.get(type(law))
    if cost is None:
        raise NotImplementedError(f"no operation count for the classical law {type(law).__name__}")
    parts = {
        "kinematics": 72 + 14 + 45 + 30,
        "law (S, CC)": int(cost(law)),
        "force": APPLY_4 + 12 * 6,
        # B (6 x 12), CC B (6 x 6 x 12), ten 3x3 blocks of B^T (CC B) over 6 rows, geometric terms
        # (V0 applied to the rows of CC and to the geometric terms)
        "element matrix": 6 * 12 * 4 + 6 * 12 * 12 + 10 * 9 * 12 + 10 * 6 + 36 + 10,
        "assembly": 6 * 9 + 4 * 9,
    }
    return OpCount("classical", parts)


def model(material: Material) -> dict:
    """Both counts and the predicted classical/mjed ratio of compute-bound kernels."""
    m, c = mjed_flops(material), classical_flops(material)
    return {"mjed": m.to_dict(), "classical": c.to_dict(), "predicted_ratio": c.total / m.total}
