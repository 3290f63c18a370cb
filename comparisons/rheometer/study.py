"""The simulated rheometer of the paper's Fig. 3: a frequency sweep in torsion.

A cylindrical sample sits between two plates: the lower face is clamped, the upper face is
rotated about the axis by theta(t) = theta0 sin(omega t). The material is St Venant-Kirchhoff
with G0 = 770 Pa and the two-term Prony series (alpha_1, alpha_2) = (0.235, 0.333),
(tau_1, tau_2) = (0.27 s, 0.03 s). For each omega the sample is integrated by mjed's implicit
Euler with the visco-hyperelastic force field, the torque on the upper plate is fitted by a
sine and a cosine over whole periods, and

    G*(omega) / G0 = (torque fit: sin and cos coefficients) / (elastic torque at theta0).

Normalising by the elastic response of the same mesh makes the spatial discretisation cancel.

Choices, and why:

- Sample: 20 mm diameter (the AR2000's plate) and 4 mm high; about 1000 tetrahedra.
  Poisson's ratio 0.45 (lam = 2 G0 nu / (1 - 2 nu)); torsion at small amplitude is
  isochoric, so lam hardly matters.
- Quasi-static (density 0): the moduli the paper compares are the material's, and a
  rheometer's analysis assumes no sample inertia. (With liver's density, 1050 kg/m^3, the
  first shear resonance of this sample is near c / 4h = sqrt(G0 / rho) / 4h ~ 55 Hz ~ 340 rad/s,
  right at the top of the sweep, so inertia would not be negligible there.)
- Amplitude theta0 = 1e-6 rad (shear strain about 2.5e-6): in the linear range the
  displacement field is the elastic one times a scalar history (correspondence principle),
  so the torque obeys the scalar backward-Euler recursion and the sweep can be checked
  against its exact discrete transfer function. Larger amplitudes add O(theta0^2) geometric
  nonlinearity; smaller ones lose digits to cancellation in F - I.
- The elastic torque is the odd part (T(+theta0) - T(-theta0)) / 2 of one linearised static
  step: the even (theta0^2) part of a generic unstructured mesh's torque would otherwise bias
  the normalisation by O(theta0).
- Transients: the history starts at zero, so the torque carries, on top of the steady state,
  c_i b_i^n for each Prony term (the free solutions of the recursion; b_i = tau_i/(dt + tau_i)).
  They are fitted together with sin, cos, a constant and the second harmonic (which the
  even part of the nonlinearity produces), so one warm-up period is enough whatever
  omega tau_i is: no need to integrate for many tau_1 before measuring.
- Speed: one linearised solve per step (SOFA's scheme), CG warm-started from the last
  increment, and the viscous field reuses the accepted state's evaluation for the next step.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from typing import Callable, Optional, Sequence

import numpy as np

import mjed
from comparisons.rheometer.records import (
    ErrorSummary,
    FrequencyRow,
    FrequencyRun,
    RheometerResult,
    RheometerSpec,
    SampleMesh,
    Sweep,
    SweepErrors,
)
from mjed.integrator import ImplicitEuler, Prescribed
from mjed.solvers import LinearSolverOptions
from mjed.viscous import ViscoHyperelasticForceField, prony_coefficients

__all__ = [
    "KEY",
    "TITLE",
    "DISCRETE_TOL",
    "RheometerSpec",
    "RheometerResult",
    "FrequencyRow",
    "Sweep",
    "TorsionSample",
    "run_rheometer",
    "sweep",
    "fit_harmonic",
    "elastic_torque",
    "QUICK_SPEC",
    "rheometer_spec",
    "rheometer_study",
]

KEY = "rheometer"
TITLE = "Rheometer frequency sweep (paper Fig. 3)"

#: The sweep must reproduce the exact backward-Euler transfer function to this relative error
#: (what is left is O(amplitude^2) geometric nonlinearity and round-off, about 1e-10).
DISCRETE_TOL = 1e-7


#: A complete but small run (a few seconds).
QUICK_SPEC = RheometerSpec(
    target_cells=300, samples_per_period=32, n_frequencies=5, measured_periods=1
)


@dataclass(frozen=True)
class TorsionSample:
    """A sample between two plates normal to z: lower face (z = min) clamped, upper face
    (z = max) rotated about the z axis through the origin.
    """

    mesh: mjed.TetMesh
    bottom: np.ndarray
    top: np.ndarray

    @classmethod
    def from_arrays(cls, points, cells) -> "TorsionSample":
        mesh = mjed.TetMesh(points, cells)
        z = mesh.points[:, 2]
        tol = 1e-9 * (z.max() - z.min())
        bottom, top = np.flatnonzero(z <= z.min() + tol), np.flatnonzero(z >= z.max() - tol)
        if len(bottom) < 3 or len(top) < 3:
            raise ValueError(
                f"need at least 3 nodes on each plate, got {len(bottom)} (bottom) and {len(top)} "
                "(top)"
            )
        return cls(mesh, bottom, top)

    def rotation(self, theta: float) -> np.ndarray:
        """Displacement (k, 3) of the top nodes for a rigid rotation by theta about z."""
        X = self.mesh.points[self.top]
        c, s = np.cos(theta), np.sin(theta)
        return np.c_[
            (c - 1.0) * X[:, 0] - s * X[:, 1], s * X[:, 0] + (c - 1.0) * X[:, 1], np.zeros(len(X))
        ]

    def torque(self, reaction: np.ndarray) -> float:
        """z-moment of the reactions (n, 3) on the top nodes, with rest lever arms."""
        X, R = self.mesh.points[self.top], reaction[self.top]
        return float(np.sum(X[:, 0] * R[:, 1] - X[:, 1] * R[:, 0]))

    def integrator(
        self, model, dt: float, theta: Callable[[float], float], **options
    ) -> ImplicitEuler:
        """Quasi-static (density 0) implicit Euler with the top following theta(t)."""
        return ImplicitEuler(
            self.mesh,
            model,
            0.0,
            dt=dt,
            gravity=None,
            fixed_nodes=self.bottom,
            prescribed=Prescribed(self.top, lambda t: self.rotation(theta(t))),
            **options,
        )


_SOLVER = dict(solver=LinearSolverOptions(cg_tol=1e-13, max_iterations=20000))


def elastic_torque(sample: TorsionSample, material, amplitude: float) -> float:
    """Odd part of the static torque at +-amplitude, one linearised step from rest (N m)."""
    torques = []
    for sign in (1.0, -1.0):
        field = mjed.HyperelasticForceField(sample.mesh, material)
        report = sample.integrator(
            field, 1.0, lambda t, s=sign: s * amplitude * t, **_SOLVER
        ).step()
        torques.append(sample.torque(report.reaction))
    return 0.5 * (torques[0] - torques[1])


def fit_harmonic(t: np.ndarray, y: np.ndarray, omega: float, decays=(), n0: int = 0) -> complex:
    """Least-squares fit of y(t_k) = A sin(omega t) + B cos(omega t) + c + (2nd harmonic)
    + sum_i c_i d_i^(k - n0); returns A + iB.

    Args:
        t, y: (K,) sample times and values, over whole periods.
        decays: per-step factors d_i of known transients (the Prony b_i).
        n0: step index of the first sample (the transients are normalised there).
    """
    k = np.arange(len(t))
    cols = [
        np.sin(omega * t),
        np.cos(omega * t),
        np.ones_like(t),
        np.sin(2 * omega * t),
        np.cos(2 * omega * t),
    ]
    cols += [np.power(d, k.astype(float)) for d in decays]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), y, rcond=None)
    return complex(coef[0], coef[1])


def simulate_frequency(
    sample: TorsionSample, spec: RheometerSpec, omega: float, torque_elastic: float
) -> FrequencyRun:
    """One sinusoidal run at omega; G*/G0 from the fitted torque."""
    N = spec.samples_per_period
    dt = 2.0 * np.pi / (omega * N)
    field = ViscoHyperelasticForceField(sample.mesh, spec.material, prony=spec.prony)
    integ = sample.integrator(field, dt, lambda t: spec.amplitude * np.sin(omega * t), **_SOLVER)
    n_warm, n_meas = N * spec.warmup_periods, N * spec.measured_periods
    torque = np.empty(n_warm + n_meas)
    cg = 0
    for k in range(len(torque)):
        report = integ.step()
        torque[k] = sample.torque(report.reaction)
        cg += report.cg_iterations
    t = dt * np.arange(1, len(torque) + 1)
    _, b = prony_coefficients(spec.prony, dt)
    amplitude = fit_harmonic(t[n_warm:], torque[n_warm:], omega, decays=b)
    G = amplitude / (spec.amplitude * torque_elastic)
    return FrequencyRun(
        omega=float(omega),
        dt=dt,
        G=G,
        steps=len(torque),
        cg_iterations_per_step=cg / len(torque),
    )


def sweep(
    sample: TorsionSample,
    spec: RheometerSpec,
    omegas=None,
    progress: Optional[Callable[[str], None]] = None,
) -> Sweep:
    """The sweep on a given sample: moduli (Pa) and their errors against both references."""
    omegas = spec.omegas() if omegas is None else np.asarray(omegas, dtype=float)
    T_el = elastic_torque(sample, spec.material, spec.amplitude) / spec.amplitude
    rows = []
    for omega in omegas:
        row = _frequency_row(spec, simulate_frequency(sample, spec, omega, T_el))
        rows.append(row)
        if progress:
            progress(
                f"omega = {omega:.3g} rad/s: G' = {row.G_storage:.2f} Pa, G'' = {row.G_loss:.2f} Pa"
            )
    errors = SweepErrors(
        continuous=ErrorSummary.of(np.array([r.rel_err_continuous for r in rows])),
        discrete=ErrorSummary.of(np.array([r.rel_err_discrete for r in rows])),
    )
    return Sweep(elastic_torque_per_radian=T_el, frequencies=tuple(rows), errors=errors)


def _frequency_row(spec: RheometerSpec, run: FrequencyRun) -> FrequencyRow:
    """One run's moduli (Pa) beside the continuous and the discrete references at its dt."""
    G, omega = run.G, run.omega
    cont = complex(spec.prony.complex_modulus(omega))
    disc = complex(spec.prony.discrete_modulus(omega, run.dt))
    return FrequencyRow(
        omega=omega,
        dt=run.dt,
        steps=run.steps,
        cg_iterations_per_step=run.cg_iterations_per_step,
        frequency_hz=float(omega / (2 * np.pi)),
        G_storage=spec.G0 * G.real,
        G_loss=spec.G0 * G.imag,
        continuous=(spec.G0 * cont.real, spec.G0 * cont.imag),
        discrete=(spec.G0 * disc.real, spec.G0 * disc.imag),
        rel_err_continuous=(_rel(G.real, cont.real), _rel(G.imag, cont.imag)),
        rel_err_discrete=(_rel(G.real, disc.real), _rel(G.imag, disc.imag)),
    )


def run_rheometer(
    *,
    quick: bool = False,
    out: Optional[str] = None,
    json_path: Optional[str] = None,
    spec: Optional[RheometerSpec] = None,
    progress: Optional[Callable[[str], None]] = None,
) -> RheometerResult:
    """The whole study: gmsh cylinder, sweep, figure (if ``out``), JSON (if ``json_path``).

    Returns:
        The spec, the mesh's counts, the elastic torque, the per-frequency moduli and errors,
        the mean/max relative errors against the continuous and the discrete moduli, the figure
        paths and the elapsed time; its ``to_dict()`` is what ``json_path`` receives.
    """
    import meshes

    spec = spec or (QUICK_SPEC if quick else RheometerSpec())
    t0 = time.perf_counter()
    points, cells = meshes.cylinder(spec.radius, spec.height, spec.target_cells)
    sample = TorsionSample.from_arrays(points, cells)
    mesh = SampleMesh(
        n_nodes=sample.mesh.n_nodes,
        n_cells=sample.mesh.n_cells,
        n_bottom=len(sample.bottom),
        n_top=len(sample.top),
    )
    result = RheometerResult.of(spec, mesh, sweep(sample, spec, progress=progress))
    figures = []
    if out:
        os.makedirs(out, exist_ok=True)
        figures.append(plot_moduli(result, os.path.join(out, "rheometer_moduli.png")))
    result = replace(result, figures=tuple(figures), elapsed_s=time.perf_counter() - t0)
    if json_path:
        from common.options import write_json

        write_json(json_path, result.to_dict())
    return result


def plot_moduli(result: RheometerResult, path: str) -> str:
    """Fig. 3 style: G' and G'' against omega on a log axis; errors in a second panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = result.spec
    rows = result.frequencies
    w = np.array([r.omega for r in rows])
    fine = np.geomspace(w.min() / 1.5, w.max() * 1.5, 300)
    G = spec.G0 * spec.prony.complex_modulus(fine)
    fig, (ax, ax_err) = plt.subplots(
        2, 1, figsize=(6.4, 6.4), sharex=True, gridspec_kw={"height_ratios": [2, 1]}
    )
    ax.semilogx(fine, G.real, "-", color="C0", lw=1, label="G' generalised Maxwell")
    ax.semilogx(fine, G.imag, "-", color="C1", lw=1, label="G'' generalised Maxwell")
    ax.semilogx(
        w,
        [r.discrete[0] for r in rows],
        "+",
        color="k",
        ms=9,
        label="backward-Euler recursion (exact)",
    )
    ax.semilogx(w, [r.discrete[1] for r in rows], "+", color="k", ms=9)
    ax.semilogx(
        w, [r.G_storage for r in rows], "o", mfc="none", color="C0", label="G' simulated (mjed)"
    )
    ax.semilogx(
        w, [r.G_loss for r in rows], "s", mfc="none", color="C1", label="G'' simulated (mjed)"
    )
    for tau in spec.taus:
        ax.axvline(1.0 / tau, color="0.8", lw=0.8, zorder=0)
    ax.set_ylabel("modulus (Pa)")
    ax.set_title(
        f"Simulated rheometer: StVK G0 = {spec.G0:g} Pa, alpha = {spec.alphas}, tau = "
        f"{spec.taus} s",
        fontsize=8,
    )
    ax.legend(fontsize=7)
    _plot_errors(ax_err, w, rows)
    ax_err.set_xlabel("angular frequency omega (rad/s)")
    ax_err.set_ylabel("relative error")
    ax_err.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_errors(ax, w: np.ndarray, rows: Sequence[FrequencyRow]) -> None:
    """The lower panel: each modulus' relative error against both references."""
    for j, (name, marker) in enumerate((("G'", "o"), ("G''", "s"))):
        colour = "C2" if j == 0 else "C3"
        continuous = [r.rel_err_continuous[j] for r in rows]
        discrete = [max(r.rel_err_discrete[j], 1e-17) for r in rows]  # zero on a log axis
        ax.loglog(
            w, continuous, marker + "-", mfc="none", color=colour, label=f"{name} vs continuous"
        )
        ax.loglog(w, discrete, marker + "--", mfc="none", color=colour, label=f"{name} vs discrete")


#: The command-line options of ``mjed-verify dma`` that override a field of the spec.
SPEC_OPTIONS = {
    "cells": "target_cells",
    "frequencies": "n_frequencies",
    "samples_per_period": "samples_per_period",
    "amplitude": "amplitude",
}


def rheometer_spec(quick: bool = False, **overrides) -> RheometerSpec:
    """The default (or quick) spec with the command-line overrides (keys of SPEC_OPTIONS; None =
    keep).

    Raises:
        ValueError: an override out of range (the spec says which).
    """
    spec = QUICK_SPEC if quick else RheometerSpec()
    return replace(spec, **{SPEC_OPTIONS[k]: v for k, v in overrides.items() if v is not None})


def rheometer_study(
    *,
    quick: bool = False,
    out_dir: Optional[str] = None,
    figure_root: Optional[str] = None,
    progress: Optional[Callable[[str], None]] = None,
    **overrides,
):
    """The rheometer study as a typed result.

    Args:
        quick: the small spec (QUICK_SPEC); the result lists what that leaves out.
        out_dir: where the figure goes (None: no figure).
        figure_root: figure paths (blocks and data) are made relative to it (the report's run dir).
        overrides: cells, frequencies, samples_per_period, amplitude (as ``mjed-verify dma``).

    Returns:
        A :class:`common.result.StudyResult`. One tolerance: the largest relative error of
        G' and G'' against the exact backward-Euler response, <= DISCRETE_TOL. ``data`` is the
        JSON form (``to_dict()``) of :func:`run_rheometer`'s :class:`RheometerResult`.
    """
    from common.reproduce import command
    from common.result import Check, StudyResult

    spec = rheometer_spec(quick, **overrides)
    res = run_rheometer(spec=spec, out=out_dir, progress=progress)
    e = res.errors
    full = rheometer_spec(False, **overrides)
    not_covered = []
    if quick and spec != full:
        not_covered.append(
            f"quick: {spec.n_frequencies} frequencies, about {spec.target_cells} cells, "
            f"{spec.samples_per_period} steps per period and {spec.measured_periods} measured "
            f"period(s) instead of {full.n_frequencies}, {full.target_cells}, "
            f"{full.samples_per_period} and {full.measured_periods}"
        )
    check = Check(
        "G', G'' against the exact backward-Euler response: largest relative error",
        e.discrete.max,
        DISCRETE_TOL,
    )
    if figure_root:  # the report's run directory is renamed when done: keep paths relative to it
        res = replace(res, figures=tuple(os.path.relpath(p, figure_root) for p in res.figures))
    headline = (
        f"against Maxwell mean {100 * e.continuous.mean:.1f} %, max "
        f"{100 * e.continuous.max:.1f} %; against the exact discrete response max "
        f"{e.discrete.max:.1e}"
    )
    return StudyResult.from_checks(
        KEY,
        TITLE,
        [check],
        headline=headline,
        command=command("dma", quick=quick, **overrides),
        not_covered=tuple(not_covered),
        data=res.to_dict(),
        blocks=tuple(_blocks(spec, res)),
        seconds=res.elapsed_s,
    )


def _blocks(spec: RheometerSpec, res: RheometerResult) -> list:
    """The figure, the set-up in words, the error summary and the per-frequency table."""
    from common.blocks import Figure, Paragraph, Table

    e = res.errors
    caption = (
        "G' and G'' of the simulated rheometer (markers) against the continuous generalised "
        "Maxwell moduli and the exact backward-Euler response (lines), as in the paper's Fig. 3"
    )
    blocks: list = [Figure(p, caption) for p in res.figures]
    blocks.append(
        Paragraph(
            "A simulated rheometer twists a visco-hyperelastic cylinder sinusoidally: "
            f"{2e3 * spec.radius:g} mm across and {1e3 * spec.height:g} mm high "
            f"({res.mesh.n_cells} cells), lower face clamped, upper face twisted by "
            f"{spec.amplitude:g} rad; St Venant-Kirchhoff G0 = {spec.G0:g} Pa with Prony alphas "
            f"{spec.alphas} and taus {spec.taus} s; {spec.samples_per_period} backward-Euler steps "
            "per period. The storage and loss moduli fitted from the torque are compared with the "
            "generalised Maxwell model and with the exact response of the backward-Euler Prony "
            "recursion."
        )
    )
    blocks.append(
        Table(
            ("reference", "mean relative error", "max relative error"),
            [
                ("continuous generalised Maxwell", e.continuous.mean, e.continuous.max),
                ("exact discrete (backward Euler)", e.discrete.mean, e.discrete.max),
            ],
            caption="The gap to the continuous moduli is the time step's own error, not a check "
            "(the paper reports 5 % against experiment).",
        )
    )
    rows = [
        (
            f.frequency_hz,
            f.omega,
            f.G_storage,
            f.continuous[0],
            f.discrete[0],
            f.G_loss,
            f.continuous[1],
            f.discrete[1],
            max(f.rel_err_discrete),
        )
        for f in res.frequencies
    ]
    header = (
        "f (Hz)",
        "omega (rad/s)",
        "G' (Pa)",
        "G' Maxwell",
        "G' discrete",
        "G'' (Pa)",
        "G'' Maxwell",
        "G'' discrete",
        "error vs discrete",
    )
    blocks.append(Table(header, rows))
    return blocks


def _rel(value: float, reference: float) -> float:
    return abs(value - reference) / abs(reference)
