"""Fig. 4 as the paper describes it: the liver oscillating under gravity, and what the time
step does to it.

The paper's Fig. 4 shows the maximum displacement of the liver over time for the three models
and says that viscosity increases the amplitude of the oscillations, porosity lying in
between. Backward Euler damps oscillations by itself: on an undamped oscillator of angular
frequency w each step multiplies the amplitude by 1 / sqrt(1 + (w dt)^2), a decay rate

    lambda_BE(dt) = ln(1 + (w dt)^2) / (2 dt),

which grows with dt (for w dt >> 1 the motion is overdamped: no oscillation at all). This
study runs the three models with the Rayleigh damping removed (``rayleigh_mass =
rayleigh_stiffness = 0``: the Prony series and the fluid keep their own dissipation) at time
steps from the paper's 0.3 s down to 0.01 s, and measures from each max-displacement curve:

- its extrema (local maxima and minima), the period (twice the mean spacing of extrema), the
  first peak and the overshoot over the final value;
- the decay rate: the slope of ln |a(e_{j+1}) - a(e_j)| over time, the successive swings
  between extrema (at least two swings are needed, else the run counts as not oscillating);
- backward Euler's lambda_BE(dt) on the angular frequency w measured at the smallest dt, for
  comparison.

It reports what is found, whatever it is: whether the models oscillate at each dt, their
amplitude ordering (largest first), and the decay rates.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable, List, Optional, Sequence

import numpy as np

from comparisons.liver.oscillation_records import (
    OscillationCurve,
    OscillationData,
    OscillationMetrics,
    OscillationRow,
)

__all__ = ["OSCILLATION_DTS", "oscillation_metrics", "euler_decay_rate", "run_oscillations"]

#: The time steps of the study: the paper's 0.3 s down to 0.01 s.
OSCILLATION_DTS = (0.3, 0.1, 0.03, 0.01)


def oscillation_metrics(
    t: Sequence[float], a: Sequence[float], *, significant: float = 5e-3
) -> OscillationMetrics:
    """Extrema, period, decay rate and overshoot of one max-displacement curve a(t) (m, s).

    A swing between successive extrema counts only when it exceeds ``significant`` times the
    final value (round-off and solver wiggles are not oscillations); the decay rate needs at
    least two such swings.
    """
    t, a = np.asarray(t, dtype=float), np.asarray(a, dtype=float)
    d = np.diff(a)
    ext = np.flatnonzero(d[:-1] * d[1:] < 0) + 1  # strict changes of direction
    out = OscillationMetrics(
        extrema=0,
        first_peak=None,
        period=None,
        decay_rate=None,
        overshoot=None,
        final=float(a[-1]),
        peak=float(a.max()),
    )
    if len(ext) < 2:
        return out
    swings = np.abs(np.diff(a[ext]))
    keep = swings > significant * abs(a[-1])
    if not keep.any():
        return out
    maxima = [k for k in ext if d[k - 1] > 0]
    mids = 0.5 * (t[ext][1:] + t[ext][:-1])
    decay_rate = None
    if keep.sum() >= 2:
        slope = np.polyfit(mids[keep], np.log(swings[keep]), 1)[0]
        decay_rate = float(-slope)
    return dataclasses.replace(
        out,
        extrema=int(keep.sum() + 1),
        first_peak=float(a[maxima[0]]),
        overshoot=float(a[maxima[0]] / a[-1]) if a[-1] > 0 else None,
        period=float(2.0 * np.mean(np.diff(t[ext])[keep])),
        decay_rate=decay_rate,
    )


def euler_decay_rate(omega: float, dt: float) -> float:
    """Backward Euler's decay rate (1/s) of an undamped oscillation of angular frequency omega."""
    return float(np.log1p((omega * dt) ** 2) / (2.0 * dt))


def _with_euler_rates(
    rows: List[OscillationRow], models: Sequence[str], smallest: float
) -> List[OscillationRow]:
    """The rows with backward Euler's own damping at each dt, on the frequency each model shows
    at the smallest dt (omega_smallest_dt and euler_decay_rate).
    """
    out = list(rows)
    for kind in models:
        ref = next(r for r in out if r.model == kind and r.dt == smallest)
        omega = 2 * np.pi / ref.period if ref.period else None
        out = [
            dataclasses.replace(
                r,
                omega_smallest_dt=omega,
                euler_decay_rate=euler_decay_rate(omega, r.dt) if omega else None,
            )
            if r.model == kind
            else r
            for r in out
        ]
    return out


def run_oscillations(
    organ,
    fixed: np.ndarray,
    params,
    *,
    dts: Sequence[float] = OSCILLATION_DTS,
    duration: float = 3.0,
    models: Sequence[str],
    force_field,
    out_dir: str,
    progress: Optional[Callable[[str], None]] = None,
) -> OscillationData:
    """Every model at every dt without Rayleigh damping; curves, metrics, figures (see module)."""
    from comparisons.liver.figures import plot_decay, plot_oscillations
    from comparisons.liver.simulation import simulate

    light = dataclasses.replace(params, rayleigh_mass=0.0, rayleigh_stiffness=0.0)
    curves, rows = [], []
    for kind in models:
        for dt in sorted(dts, reverse=True):
            if progress is not None:
                progress(f"oscillation study: {kind}, dt = {dt:g} s")
            run = simulate(kind, organ.mesh, light, fixed, duration, force_field=force_field, dt=dt)
            curves.append(OscillationCurve.of_run(run))
            metrics = oscillation_metrics(run.time, run.max_displacement)
            rows.append(OscillationRow.of_run(run, metrics))
    smallest = min(dts)
    rows = _with_euler_rates(rows, models, smallest)
    fine = {r.model: r for r in rows if r.dt == smallest}
    ordering = sorted(fine, key=lambda m: fine[m].peak, reverse=True)
    figures = [
        plot_oscillations(os.path.join(out_dir, "fig4_oscillations.png"), curves, organ.label),
        plot_decay(os.path.join(out_dir, "fig4_decay_rate.png"), rows),
    ]
    return OscillationData(
        mesh=organ.label,
        dts=tuple(dts),
        duration=duration,
        rayleigh=(0.0, 0.0),
        curves=tuple(curves),
        table=tuple(rows),
        amplitude_ordering=tuple(ordering),
        amplitude_ordering_dt=smallest,
        figures=tuple(figures),
    )
