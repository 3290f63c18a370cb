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
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

__all__ = ["OSCILLATION_DTS", "oscillation_metrics", "euler_decay_rate", "run_oscillations"]

#: The time steps of the study: the paper's 0.3 s down to 0.01 s.
OSCILLATION_DTS = (0.3, 0.1, 0.03, 0.01)


def oscillation_metrics(
    t: Sequence[float], a: Sequence[float], *, significant: float = 5e-3
) -> Dict:
    """Extrema, period, decay rate and overshoot of one max-displacement curve a(t) (m, s).

    A swing between successive extrema counts only when it exceeds ``significant`` times the
    final value (round-off and solver wiggles are not oscillations); the decay rate needs at
    least two such swings.
    """
    t, a = np.asarray(t, dtype=float), np.asarray(a, dtype=float)
    d = np.diff(a)
    ext = np.flatnonzero(d[:-1] * d[1:] < 0) + 1  # strict changes of direction
    out = {
        "extrema": 0,
        "first_peak": None,
        "period": None,
        "decay_rate": None,
        "overshoot": None,
        "final": float(a[-1]),
        "peak": float(a.max()),
    }
    if len(ext) < 2:
        return out
    swings = np.abs(np.diff(a[ext]))
    keep = swings > significant * abs(a[-1])
    if not keep.any():
        return out
    out["extrema"] = int(keep.sum() + 1)
    maxima = [k for k in ext if d[k - 1] > 0]
    out["first_peak"] = float(a[maxima[0]])
    out["overshoot"] = float(a[maxima[0]] / a[-1]) if a[-1] > 0 else None
    mids = 0.5 * (t[ext][1:] + t[ext][:-1])
    out["period"] = float(2.0 * np.mean(np.diff(t[ext])[keep]))
    if keep.sum() >= 2:
        slope = np.polyfit(mids[keep], np.log(swings[keep]), 1)[0]
        out["decay_rate"] = float(-slope)
    return out


def euler_decay_rate(omega: float, dt: float) -> float:
    """Backward Euler's decay rate (1/s) of an undamped oscillation of angular frequency omega."""
    return float(np.log1p((omega * dt) ** 2) / (2.0 * dt))


#: What the oscillation study keeps of each run for its figure and results.json.
_CURVE_KEYS = (
    "model",
    "dt",
    "time",
    "max_displacement",
    "error",
    "steps",
    "steps_planned",
    "steps_split",
    "substeps_total",
    "fps",
)


def _add_euler_rates(rows: List[Dict], models: Sequence[str], smallest: float) -> None:
    """Backward Euler's own damping at each dt, on the frequency each model shows at the
    smallest dt (added to the rows as omega_smallest_dt and euler_decay_rate).
    """
    for kind in models:
        ref = next(r for r in rows if r["model"] == kind and r["dt"] == smallest)
        omega = 2 * np.pi / ref["period"] if ref["period"] else None
        for r in rows:
            if r["model"] == kind:
                r["omega_smallest_dt"] = omega
                r["euler_decay_rate"] = euler_decay_rate(omega, r["dt"]) if omega else None


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
) -> Dict:
    """Every model at every dt without Rayleigh damping; curves, metrics, figures (see module)."""
    from comparisons.liver_figures import plot_decay, plot_oscillations
    from comparisons.liver_simulation import simulate

    light = dataclasses.replace(params, rayleigh_mass=0.0, rayleigh_stiffness=0.0)
    curves, rows = [], []
    for kind in models:
        for dt in sorted(dts, reverse=True):
            if progress is not None:
                progress(f"oscillation study: {kind}, dt = {dt:g} s")
            run = simulate(kind, organ.mesh, light, fixed, duration, force_field=force_field, dt=dt)
            run.pop("_pressure_snapshot", None)
            curves.append({k: run[k] for k in _CURVE_KEYS})
            rows.append(
                {
                    "model": kind,
                    "dt": dt,
                    "completed": run["error"] is None,
                    "error": run["error"],
                    "steps_split": run["steps_split"],
                    **oscillation_metrics(run["time"], run["max_displacement"]),
                }
            )
    smallest = min(dts)
    _add_euler_rates(rows, models, smallest)
    fine = {r["model"]: r for r in rows if r["dt"] == smallest}
    ordering = sorted(fine, key=lambda m: fine[m]["peak"], reverse=True)
    figures = [
        plot_oscillations(os.path.join(out_dir, "fig4_oscillations.png"), curves, organ.label),
        plot_decay(os.path.join(out_dir, "fig4_decay_rate.png"), rows),
    ]
    return {
        "mesh": organ.label,
        "dts": list(dts),
        "duration": duration,
        "rayleigh": [0.0, 0.0],
        "curves": curves,
        "table": rows,
        "amplitude_ordering": ordering,
        "amplitude_ordering_dt": smallest,
        "figures": figures,
    }
