"""What the Terzaghi consolidation check records (``comparisons.liver.terzaghi.run_terzaghi``), as
typed records.

The liver study keeps it in ``LiverData.terzaghi`` (key ``terzaghi`` of its ``results.json``);
``to_dict()`` gives that JSON form, ``from_dict()`` reads it back, refusing a missing,
unexpected or bad key by name. Pressures and moduli in Pa, times in s, lengths in m.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Tuple

from common.json_fields import JSONFields, JSONRecord
from common.record_fields import RecordFields

__all__ = ["TerzaghiTime", "TerzaghiResult"]


@dataclass(frozen=True)
class TerzaghiTime(JSONRecord):
    """One checked instant: its dimensionless time T_v = c_v t / h^2 and the relative L2 error
    ||P - P_exact|| / ||P_exact|| of the nodal pressure along the column's axis.
    """

    T_v: float
    relative_l2_error: float

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.real("T_v", positive=True)
        f.real("relative_l2_error")
        if self.relative_l2_error < 0:
            raise f.refusal("relative_l2_error", "a number >= 0", self.relative_l2_error)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class TerzaghiResult(JSONRecord):
    """The coupled column against the series solution (``comparisons.liver.terzaghi``).

    figures: the PNG of the pressure profiles (none when not asked for); n_layers, dt (s),
    coupling_iterations: the discretisation; B: Skempton's coefficient K_lim / (K_lim + M);
    c_v: the consolidation coefficient (m^2/s); K_lim (Pa); constrained_modulus: M = lam + 2 mu
    (Pa); times: one :class:`TerzaghiTime` per checked instant (at least one).
    """

    figures: Tuple[str, ...]
    n_layers: int
    dt: float
    coupling_iterations: int
    B: float
    c_v: float
    K_lim: float
    constrained_modulus: float
    times: Tuple[TerzaghiTime, ...]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.texts("figures")
        f.count("n_layers", minimum=1)
        f.count("coupling_iterations", minimum=1)
        for key in ("dt", "B", "c_v", "K_lim", "constrained_modulus"):
            f.real(key, positive=True)
        f.records("times", TerzaghiTime)
        if not self.times:
            raise f.refusal("times", "at least one checked instant", self.times)

    @property
    def worst_error(self) -> float:
        """The largest relative L2 pressure error over the checked instants."""
        return max(t.relative_l2_error for t in self.times)

    def to_dict(self) -> dict:
        """The JSON form, keys in the order results.json has always had them."""
        out = {k: getattr(self, k) for k in ("n_layers", "dt", "coupling_iterations")}
        out.update(
            B=self.B, c_v=self.c_v, K_lim=self.K_lim, constrained_modulus=self.constrained_modulus
        )
        return {"figures": list(self.figures), **out, "times": [t.to_dict() for t in self.times]}

    @classmethod
    def from_fields(cls, f: JSONFields) -> "TerzaghiResult":
        return f.dataclass(cls, times=f.records("times", TerzaghiTime))
