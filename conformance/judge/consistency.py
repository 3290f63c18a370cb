"""Is the engine's stiffness the derivative of its own force (and its force of its own energy)?

The probes are the same model at x + d_k with d_k = d / 2^k. The Taylor remainders

    r_k = f(x + d_k) - f(x) + K d_k            (vector)
    s_k = W(x + d_k) - W(x) + f . d_k          (scalar)

are fitted as t A + t^2 B + t^3 C with t = 2^-k. A consistent tangent has A = 0 (remainder of
order two); A t_0 is the part of K d that is not the derivative of the force along d, so

    inconsistency = ||A|| / ||K d||

is a relative figure independent of the step. The cubic fit is not exact: it leaves the
t^4, t^5, ... terms, whose size grows with the energy's higher derivatives along d, and the
round-off of the differences. On a sliver (a cell whose height is a few hundredths of its
edges) a step of 1e-4 of the mean edge is a strain of several 1e-3 in that cell, and the fit
leaves up to 2e-4 for an exactly consistent engine (kits now scale each node's step by its
thinnest cell, :func:`conformance.kit.cases.probe_lengths`, but older kits do not, and round-off
remains). A fixed limit cannot be calibrated for every mesh and state, so each case is
calibrated:

* **the floor**: the oracle's force (and energy) at the same probes, with its exact tangent,
  go through the same fit. What the fit leaves for the oracle, ||A_o|| / ||K d||, is what it
  leaves on this case for any engine with the same energy. The floor is that, or the round-off
  in the difference of the two remainders if larger (the part of r - r_o that no cubic in t
  explains, carried through the fit: a tangent error is linear in t and adds nothing to it);
* **the excess**: ||A - A_o|| / ||K d||, the part of the engine's linear remainder that the
  oracle's remainder on the same probes does not have. The fit is linear in the data, so the
  higher-order terms they share cancel exactly; what is left is round-off, the higher-order
  terms of the *difference* between the engine's energy and the oracle's, and any
  inconsistency of the engine's tangent;
* **the limit**: max(PROBE_TOL, FLOOR_FACTOR x floor). The stiffness is called inconsistent
  with the force when the excess is above it. An engine with the oracle's energy has an excess
  at the level of the floor's round-off (on the corpus of hard meshes, python -m
  conformance.corpus, the largest excess is 2.2e-5 where the floor is 1.6e-5: Costa on a cap
  under a strong random field, where both remainders are mostly round-off); an engine with
  another, consistent energy has the higher-order terms of the difference, which FLOOR_FACTOR
  covers as long as that difference's fourth derivatives along d stay within ten times the
  oracle's.

Every figure is finite, or the result says why it could not be measured (``note``, and
``non_finite`` when float64 overflowed): a NaN is never read as a pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp

__all__ = [
    "RESOLUTION",
    "PROBE_TOL",
    "ENERGY_PROBE_TOL",
    "FLOOR_FACTOR",
    "Consistency",
    "ReferenceProbes",
    "consistency",
    "safe_norm",
]

#: Smallest relative inconsistency of K with the engine's own force that is called inconsistent.
#: On a well-shaped mesh the fit's floor is 1e-8 or less (Costa, the stiffest exponential, 3e-10
#: on cube-small), so this is the limit there; on a sliver the case's floor sets it.
PROBE_TOL = 1e-6

#: The same for the force against the engine's energy. Energy differences over a step of 1e-4 h
#: cancel about four digits of the total energy, summed over every cell, so the smallest limit
#: is looser; a force that is not the derivative of the energy (a factor, a missing term) is off
#: by far more.
ENERGY_PROBE_TOL = 1e-4

#: Limit = max(tolerance, FLOOR_FACTOR x the floor measured through the oracle on the same probes).
FLOOR_FACTOR = 10.0

#: A limit above this is no test: the probes do not resolve the tangent on the case (an engine
#: in float32, whose round-off over a step of 1e-4 is a few per cent of K d). The result is then
#: "not resolved", neither consistent nor not.
RESOLUTION = 1e-2


@dataclass(frozen=True)
class ReferenceProbes:
    """The oracle at the base state and the probes, to calibrate the fit on this case.

    force: (n, 3) [N]; stiffness: (3n, 3n) [N/m]; energy [J];
    probe_forces: one (n, 3) per probe, in step order; probe_energies: one per probe [J].
    """

    force: np.ndarray
    stiffness: sp.spmatrix
    energy: float
    probe_forces: Tuple[np.ndarray, ...]
    probe_energies: Tuple[float, ...]


@dataclass(frozen=True)
class Consistency:
    """The probes' verdict on the engine against itself.

    force_stiffness: the engine's relative inconsistency ||A|| / ||K d|| (None: not measured);
    stiffness_floor: what the fit leaves for the oracle on the same probes (None: no oracle);
    stiffness_excess: ||A - A_o|| / ||K d|| (None without the oracle);
    stiffness_limit: the limit the excess (or, without the oracle, the inconsistency) is held to;
    energy_*: the same for the force against the engine's energy (None without energies);
    rates_*: Taylor rates log2(|r_k| / |r_k+1|) (2 when consistent, 1 when not);
    note: why something was not measured;
    non_finite: a figure could not be computed in float64 (the case cannot pass on it).
    """

    force_stiffness: Optional[float]
    energy_force: Optional[float]
    rates_force: Sequence[float] = ()
    rates_energy: Sequence[float] = ()
    note: str = ""
    stiffness_floor: Optional[float] = None
    stiffness_excess: Optional[float] = None
    stiffness_limit: float = PROBE_TOL
    energy_floor: Optional[float] = None
    energy_excess: Optional[float] = None
    energy_limit: float = ENERGY_PROBE_TOL
    non_finite: bool = False

    def __post_init__(self) -> None:
        for name in (
            "force_stiffness",
            "energy_force",
            "stiffness_floor",
            "stiffness_excess",
            "energy_floor",
            "energy_excess",
            "stiffness_limit",
            "energy_limit",
        ):
            v = getattr(self, name)
            if v is not None and not np.isfinite(v):
                raise ValueError(
                    f"Consistency.{name} = {v}: a figure must be finite or None with a note"
                )

    @property
    def stiffness_statistic(self) -> Optional[float]:
        """The figure held to ``stiffness_limit``: the excess over the oracle, else the
        inconsistency.
        """
        return self.stiffness_excess if self.stiffness_excess is not None else self.force_stiffness

    @property
    def energy_statistic(self) -> Optional[float]:
        return self.energy_excess if self.energy_excess is not None else self.energy_force

    @property
    def stiffness_consistent(self) -> Optional[bool]:
        s = self.stiffness_statistic
        if s is None or self.stiffness_limit > RESOLUTION:
            return None
        return bool(s <= self.stiffness_limit)

    @property
    def force_consistent(self) -> Optional[bool]:
        s = self.energy_statistic
        if s is None or self.energy_limit > RESOLUTION * ENERGY_PROBE_TOL / PROBE_TOL:
            return None
        return bool(s <= self.energy_limit)

    def to_dict(self) -> dict:
        return {
            "force_stiffness": self.force_stiffness,
            "energy_force": self.energy_force,
            "stiffness_floor": self.stiffness_floor,
            "stiffness_excess": self.stiffness_excess,
            "stiffness_limit": self.stiffness_limit,
            "energy_floor": self.energy_floor,
            "energy_excess": self.energy_excess,
            "energy_limit": self.energy_limit,
            "rates_force": [_json_rate(r) for r in self.rates_force],
            "rates_energy": [_json_rate(r) for r in self.rates_energy],
            "note": self.note,
            "non_finite": self.non_finite,
        }


def _json_rate(r: float) -> Optional[float]:
    """A rate is NaN when a remainder is exactly zero (nothing to divide): null in JSON."""
    return float(r) if np.isfinite(r) else None


def safe_norm(a) -> float:
    """Euclidean (Frobenius) norm without overflow: values near 1e300 still give a finite figure
    when the norm itself is representable. a: ndarray or scipy sparse matrix.
    """
    v = np.asarray(a.data if sp.issparse(a) else a, dtype=np.float64).ravel()
    if v.size == 0:
        return 0.0
    m = float(np.max(np.abs(v)))
    if m == 0.0 or not np.isfinite(m):
        return m
    return m * float(np.linalg.norm(v / m))


def _linear_coefficient(t: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A of r(t) = t A + t^2 B + t^3 C, least squares over the probes (r: (k,) or (k, N))."""
    V = np.stack([t, t**2, t**3][: max(1, min(3, len(t) - 1))], axis=1)
    coef, *_ = np.linalg.lstsq(V, r.reshape(len(t), -1), rcond=None)
    return coef[0]


def _noise_in_linear_coefficient(t: np.ndarray, r: np.ndarray) -> float:
    """Round-off in the fitted A of r (k, N): the part of r that no cubic in t explains (the
    residual of the fit, k - 3 degrees of freedom), propagated to A through the fit. A tangent
    error is exactly linear in t and leaves no residual; round-off does. 0 with 3 probes or
    fewer (nothing to measure it with).
    """
    k = len(t)
    if k <= 3:
        return 0.0
    V = np.stack([t, t**2, t**3], axis=1)
    coef, *_ = np.linalg.lstsq(V, r.reshape(k, -1), rcond=None)
    residual = safe_norm(r.reshape(k, -1) - V @ coef)
    gain = float(np.linalg.norm(np.linalg.pinv(V)[0]))
    return float(gain * residual / np.sqrt(k - 3))


def _rates(norms: List[float]) -> List[float]:
    return [
        float(np.log2(a / b)) if a > 0 and b > 0 and np.isfinite(a / b) else float("nan")
        for a, b in zip(norms, norms[1:])
    ]


def _force_remainders(x, f, K, probe_x, probe_f) -> np.ndarray:
    """(k, 3n) r_k = f(x + d_k) - f(x) + K d_k."""
    return np.array(
        [
            np.asarray(fk).ravel() - np.asarray(f).ravel() + K @ (np.asarray(xk) - x).ravel()
            for xk, fk in zip(probe_x, probe_f)
        ]
    )


def _energy_remainders(x, f, W, probe_x, probe_W) -> np.ndarray:
    """(k,) s_k = W(x + d_k) - W(x) + f . d_k."""
    return np.array(
        [
            float(Wk) - W + float(np.sum(np.asarray(f) * (np.asarray(xk) - x)))
            for xk, Wk in zip(probe_x, probe_W)
        ]
    )


def consistency(
    x: np.ndarray,
    f: np.ndarray,
    K: sp.spmatrix,
    W: Optional[float],
    probes: Sequence[tuple],
    reference: Optional[ReferenceProbes] = None,
    roundoff: float = 2.0**-53,
) -> Consistency:
    """Taylor test of an engine against itself, calibrated on the oracle when ``reference`` is
    given.

    Args:
        x, f, K, W: the base state's positions (n, 3) [m], force (n, 3) [N], stiffness (3n, 3n)
            [N/m], energy [J] or None.
        probes: (x_k, f_k, W_k) in step order k = 0, 1, ... (x_k = x + d / 2^k).
        reference: the oracle at x and at the same probes (:class:`ReferenceProbes`).
        roundoff: the engine's unit round-off (2^-24 for an engine in float32): an energy is
            one number, so its round-off cannot be measured from a fit residual; it is bounded
            from the energies' magnitude instead.
    """
    if len(probes) < 2:
        return Consistency(None, None, note=f"{len(probes)} probe result(s); at least 2 are needed")
    with np.errstate(all="ignore"):  # overflow is detected below and said in words
        return _consistency(x, f, sp.csr_matrix(K), W, probes, reference, roundoff)


def _consistency(x, f, K, W, probes, reference, roundoff) -> Consistency:
    t = np.array([0.5**k for k in range(len(probes))])
    px = [np.asarray(p[0]) for p in probes]
    r = _force_remainders(x, f, K, px, [p[1] for p in probes])
    Kd0 = safe_norm(K @ (px[0] - x).ravel())
    A = _linear_coefficient(t, r)
    fs = safe_norm(A) / Kd0 if Kd0 > 0 else safe_norm(A)
    rates_f = _rates([safe_norm(v) for v in r])
    floor = excess = None
    if reference is not None:
        r_o = _force_remainders(
            x, reference.force, sp.csr_matrix(reference.stiffness), px, reference.probe_forces
        )
        A_o = _linear_coefficient(t, r_o)
        scale = Kd0 if Kd0 > 0 else 1.0
        # The floor: the larger of what the fit leaves for the exact tangent and the round-off
        # in the engine's and the oracle's differences (what is not a polynomial in t).
        floor = max(safe_norm(A_o), _noise_in_linear_coefficient(t, r - r_o)) / scale
        excess = safe_norm(A - A_o) / scale
    notes = []
    if not all(np.isfinite(v) for v in (fs, floor or 0.0, excess or 0.0)):
        notes.append(
            "the stiffness test overflows float64 (force or stiffness values near 1e300 "
            "or beyond): "
            "not measured"
        )
        fs = floor = excess = None
    limit = PROBE_TOL if floor is None else max(PROBE_TOL, FLOOR_FACTOR * floor)

    ef = e_floor = e_excess = None
    rates_e: List[float] = []
    e_limit = ENERGY_PROBE_TOL
    if W is not None and all(p[2] is not None for p in probes):
        s = _energy_remainders(x, f, W, px, [p[2] for p in probes])
        d0 = (px[0] - x).ravel()
        # At rest f = 0: the energy change is second order, so measure against d.K d as well.
        den = abs(float(np.sum(np.asarray(f) * (px[0] - x)))) + 0.5 * abs(float(d0 @ (K @ d0)))
        a = float(abs(_linear_coefficient(t, s)[0]))
        ef = a / den if den > 0 else a
        rates_e = _rates([abs(v) for v in s])
        if reference is not None:
            s_o = _energy_remainders(
                x, reference.force, reference.energy, px, reference.probe_energies
            )
            a_o = _linear_coefficient(t, s_o)[0]
            e_scale = den if den > 0 else 1.0
            # Each energy carries about roundoff x its magnitude (times a few for the sum over
            # cells); the fit carries that to A with its gain.
            gain = float(np.linalg.norm(np.linalg.pinv(np.stack([t, t**2, t**3], axis=1))[0]))
            magnitude = 4.0 * roundoff * gain * max(abs(W), *(abs(float(p[2])) for p in probes))
            noise = _noise_in_linear_coefficient(t, s - s_o)
            e_floor = max(float(abs(a_o)), noise, magnitude) / e_scale
            e_excess = float(abs(_linear_coefficient(t, s)[0] - a_o)) / e_scale
            e_limit = (
                max(ENERGY_PROBE_TOL, FLOOR_FACTOR * e_floor) if np.isfinite(e_floor) else e_limit
            )
        if not all(np.isfinite(v) for v in (ef, e_floor or 0.0, e_excess or 0.0)):
            notes.append("the energy test overflows float64: not measured")
            ef = e_floor = e_excess = None
            e_limit = ENERGY_PROBE_TOL
    return Consistency(
        fs,
        ef,
        rates_f,
        rates_e,
        note="; ".join(notes),
        stiffness_floor=floor,
        stiffness_excess=excess,
        stiffness_limit=limit,
        energy_floor=e_floor,
        energy_excess=e_excess,
        energy_limit=e_limit,
        non_finite=bool(notes),
    )
