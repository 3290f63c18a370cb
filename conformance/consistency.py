"""Is the engine's stiffness the derivative of its own force (and its force of its own energy)?

No oracle is involved: the probes are the same model at x + d_k with d_k = d / 2^k. The Taylor
remainders

    r_k = f(x + d_k) - f(x) + K d_k            (vector)
    s_k = W(x + d_k) - W(x) + f . d_k          (scalar)

are fitted as t A + t^2 B + t^3 C with t = 2^-k. A consistent tangent has A = 0 (remainder of
order two); A t_0 is the part of K d that is not the derivative of the force along d, so

    inconsistency = ||A|| / ||K d||

is a relative figure independent of the step. Above PROBE_TOL the stiffness is called
inconsistent with the force. The rates log2(|r_k| / |r_k+1|) (2 when consistent, 1 when not)
are reported as well, as the familiar form of the same test.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["PROBE_TOL", "ENERGY_PROBE_TOL", "Consistency", "consistency"]

#: Relative inconsistency above which K is called "not the derivative of the force". The cubic
#: fit leaves the t^4 term, about (1e-4)^3 relative with eps_0 = 1e-4 h times the growth of the
#: energy's higher derivatives: 3e-10 for Costa (b_ff = 18.5) on cube-small, the worst of the
#: seven materials; round-off stays below 1e-9.
PROBE_TOL = 1e-6

#: The same for the force against the energy. Energy differences over a step of 1e-4 h cancel
#: about four digits of the total energy, summed over every cell: a correct engine shows up to
#: 1e-7 on the 20,599-cell cube (NeoHookean, compression), so the limit is looser. A force that is
#: not the derivative of the energy (a factor, a missing term) is off by far more.
ENERGY_PROBE_TOL = 1e-4


@dataclass(frozen=True)
class Consistency:
    """force_stiffness: relative inconsistency of K with the engine's own force (None: not
    measured);
    energy_force: the same for the force against the engine's energy (None without energies);
    rates_*: Taylor rates; note: why something was not measured.
    """

    force_stiffness: Optional[float]
    energy_force: Optional[float]
    rates_force: Sequence[float] = ()
    rates_energy: Sequence[float] = ()
    note: str = ""

    @property
    def stiffness_consistent(self) -> Optional[bool]:
        return None if self.force_stiffness is None else self.force_stiffness <= PROBE_TOL

    @property
    def force_consistent(self) -> Optional[bool]:
        return None if self.energy_force is None else self.energy_force <= ENERGY_PROBE_TOL

    def to_dict(self) -> dict:
        return {
            "force_stiffness": self.force_stiffness,
            "energy_force": self.energy_force,
            "rates_force": [float(r) for r in self.rates_force],
            "rates_energy": [float(r) for r in self.rates_energy],
            "note": self.note,
        }


def _linear_coefficient(t: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A of r(t) = t A + t^2 B + t^3 C, least squares over the probes (r: (k,) or (k, N))."""
    V = np.stack([t, t**2, t**3][: max(1, min(3, len(t) - 1))], axis=1)
    coef, *_ = np.linalg.lstsq(V, r.reshape(len(t), -1), rcond=None)
    return coef[0]


def _rates(norms: List[float]) -> List[float]:
    return [
        float(np.log2(a / b)) if a > 0 and b > 0 else float("nan") for a, b in zip(norms, norms[1:])
    ]


def consistency(
    x: np.ndarray, f: np.ndarray, K: sp.spmatrix, W: Optional[float], probes: Sequence[tuple]
) -> Consistency:
    """Taylor test of an engine against itself.

    Args:
        x, f, K, W: the base state's positions (n, 3), force (n, 3), stiffness (3n, 3n), energy or
        None.
        probes: (x_k, f_k, W_k) in step order k = 0, 1, ... (x_k = x + d / 2^k).
    """
    if len(probes) < 2:
        return Consistency(None, None, note=f"{len(probes)} probe result(s); at least 2 are needed")
    t = np.array([0.5**k for k in range(len(probes))])
    d = [np.asarray(p[0]) - x for p in probes]
    r = np.array(
        [np.asarray(p[1]).ravel() - f.ravel() + K @ dk.ravel() for p, dk in zip(probes, d)]
    )
    Kd0 = float(np.linalg.norm(K @ d[0].ravel()))
    A = _linear_coefficient(t, r)
    fs = float(np.linalg.norm(A)) / Kd0 if Kd0 > 0 else float(np.linalg.norm(A))
    rates_f = _rates([float(np.linalg.norm(v)) for v in r])
    ef, rates_e = None, []
    if W is not None and all(p[2] is not None for p in probes):
        s = np.array([p[2] - W + float(np.sum(f * dk)) for p, dk in zip(probes, d)])
        # At rest f = 0: the energy change is second order, so measure against d.K d as well.
        den = abs(float(np.sum(f * d[0]))) + 0.5 * abs(float(d[0].ravel() @ (K @ d[0].ravel())))
        a = float(abs(_linear_coefficient(t, s)[0]))
        ef = a / den if den > 0 else a
        rates_e = _rates([abs(v) for v in s])
    return Consistency(fs, ef, rates_f, rates_e)
