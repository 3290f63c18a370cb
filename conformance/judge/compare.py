"""Relative errors of an engine's output against the oracle, and the tolerances.

    force error     ||f - f_o||_2 / max(||f_o||_2, h ||K_o||_F)
    stiffness error ||K - K_o||_F / ||K_o||_F
    energy error    |W - W_o| / max(|W_o|, h max(||f_o||_2, h ||K_o||_F))

h is the mean edge length: at rest f_o = 0 and W_o = 0, and the denominators fall back to the
force and energy that the stiffness gives over one edge, so that a relative figure still means
"digits of agreement". The tolerance is 1e-10 on each (docs/conventions.md, "Tolerances").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from common.tolerances import FORCE_TOL, STIFFNESS_TOL
from conformance.judge.consistency import safe_norm

__all__ = [
    "FORCE_TOL",
    "grown",
    "STIFFNESS_TOL",
    "ENERGY_TOL",
    "Scales",
    "Errors",
    "errors",
    "scales",
    "Tolerances",
    "DOUBLE",
]

ENERGY_TOL = 1e-10


@dataclass(frozen=True)
class Tolerances:
    """The relative errors a case may show and still pass, at one precision.

    force, stiffness, energy: limits on the relative errors (dimensionless);
    precision: "double" or "single"; basis: how the limits were set (words, for the report).
    """

    force: float
    stiffness: float
    energy: float
    precision: str = "double"
    basis: str = "fixed at 1e-10 (docs/conventions.md, Tolerances)"
    capped: Tuple[
        str, ...
    ] = ()  # quantities whose limit was capped (not resolvable at this precision)

    def __post_init__(self) -> None:
        if self.precision not in ("double", "single"):
            raise ValueError(f"precision must be 'double' or 'single', not {self.precision!r}")
        for name in ("force", "stiffness", "energy"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Tolerances.{name} must be finite and > 0, got {v}")

    def within(self, e: "Errors", *, energy: bool = True) -> bool:
        """Force and stiffness (and, with ``energy``, a given energy) within the limits."""
        ok = e.force <= self.force and e.stiffness <= self.stiffness
        return bool(ok and (not energy or e.energy is None or e.energy <= self.energy))

    def text(self) -> str:
        if self.force == self.stiffness == self.energy:
            return f"tolerance {self.force:.1e}"
        return (
            f"tolerances force {self.force:.1e}, stiffness {self.stiffness:.1e}, energy "
            f"{self.energy:.1e} at {self.precision} precision"
        )

    def to_dict(self) -> dict:
        return {
            "force": self.force,
            "stiffness": self.stiffness,
            "energy": self.energy,
            "precision": self.precision,
            "basis": self.basis,
            "capped": list(self.capped),
        }


#: The double-precision tolerances of every case.
DOUBLE = Tolerances(FORCE_TOL, STIFFNESS_TOL, ENERGY_TOL)


@dataclass(frozen=True)
class Scales:
    """Denominators of the relative errors: force [N], stiffness [N/m], energy [J]."""

    force: float
    stiffness: float
    energy: float


@dataclass(frozen=True)
class Errors:
    """Relative errors; energy None when the engine gave none. symmetry: ||K - K^T||_F / ||K||_F."""

    force: float
    stiffness: float
    energy: Optional[float]
    symmetry: float

    @property
    def passed(self) -> bool:
        ok = self.force <= FORCE_TOL and self.stiffness <= STIFFNESS_TOL
        return bool(ok and (self.energy is None or self.energy <= ENERGY_TOL))

    def to_dict(self) -> dict:
        """Strict JSON: a figure that is not finite is null, and ``not_finite`` names it."""
        d = {
            "force": self.force,
            "stiffness": self.stiffness,
            "energy": self.energy,
            "symmetry": self.symmetry,
        }
        bad = [k for k, v in d.items() if v is not None and not np.isfinite(v)]
        d.update({k: None for k in bad})
        if bad:
            d["not_finite"] = bad
        return d


def scales(h: float, W_o: float, f_o: np.ndarray, K_o: sp.spmatrix) -> Scales:
    nK = safe_norm(K_o)
    nf = max(safe_norm(f_o), h * nK)
    return Scales(force=nf, stiffness=nK, energy=max(abs(W_o), h * nf))


def grown(s: Scales, f: np.ndarray, K: sp.spmatrix) -> Scales:
    """``s`` grown to a candidate's own force f (n, 3) and stiffness K where they are larger: a
    candidate many orders above the oracle (an exponential energy at a mistaken strain) is
    matched to its own round-off, never held to the oracle's smaller figures; a smaller one
    keeps ``s``.
    """
    k = max(1.0, safe_norm(K) / s.stiffness) if s.stiffness > 0 else 1.0
    return Scales(force=max(s.force * k, safe_norm(f)), stiffness=s.stiffness * k, energy=s.energy)


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else num


def errors(
    f: np.ndarray,
    K: sp.spmatrix,
    W: Optional[float],
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    W_o: float,
    s: Scales,
) -> Errors:
    """Relative errors of (f, K, W) against the oracle (f_o, K_o, W_o) with denominators ``s``."""
    K = sp.csr_matrix(K)
    nK = safe_norm(K)
    # Norms scaled by their largest entry: an engine writing values near 1e300 still gets finite
    # (huge) relative errors rather than inf / inf = NaN.
    with np.errstate(over="ignore", invalid="ignore"):
        return Errors(
            force=_ratio(safe_norm(np.asarray(f) - f_o), s.force),
            stiffness=_ratio(safe_norm(K - K_o), s.stiffness),
            energy=None if W is None else _ratio(abs(float(W) - W_o), s.energy),
            symmetry=_ratio(safe_norm(K - K.T), nK),
        )
