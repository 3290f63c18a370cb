"""One run of one liver model: implicit Euler steps, timed by phase, with a ParaView series.

See comparisons.liver.study for the study that calls it.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np

from comparisons.liver.records import PHASES, LiverRun, PressureSnapshot
from comparisons.liver.setup import (
    LiverParameters,
    _models,
    device_synchronizer,
    numpy_force_field,
    run_integrator,
    run_solver,
)

__all__ = ["PHASES", "simulate"]


def _phase_seconds(times) -> np.ndarray:
    """(5,) seconds of one StepTimes by PHASES: model 0 is the (visco-)hyperelastic MJED field."""
    return np.array([times.models[0], sum(times.models[1:]), times.system, times.solve, times.rest])


@dataclass
class Trajectory:
    """What one run records step by step (lists start with the state at t = 0)."""

    times: List[float] = field(default_factory=lambda: [0.0])
    amplitude: List[float] = field(default_factory=lambda: [0.0])  # max nodal |u| [m]
    cg: List[int] = field(default_factory=list)
    substeps: List[int] = field(default_factory=list)
    retries: List[list] = field(default_factory=list)
    inverted: List[int] = field(default_factory=list)
    p_max: List[float] = field(default_factory=lambda: [0.0])  # max |P| [Pa]
    factorizations: int = 0
    stepping: float = 0.0  # wall-clock seconds spent in the integrator's steps
    cpu: float = 0.0  # CPU seconds of this process in those steps
    phases: np.ndarray = field(default_factory=lambda: np.zeros(len(PHASES)))
    best_P: tuple = (0.0, None, None)  # (max |P|, P, x) for the Fig. 1 picture

    def add(self, integ, report, mesh, fluid, wall: float, cpu: float) -> None:
        self.stepping += wall
        self.cpu += cpu
        self.phases += _phase_seconds(report.times)
        self.times.append(integ.t)
        self.amplitude.append(integ.max_displacement())  # a device reduction on the GPU
        self.cg.append(report.cg_iterations)
        self.substeps.append(report.substeps)
        self.retries.append(list(report.retries))
        self.inverted.append(report.inverted_cells)
        self.factorizations += report.factorizations
        if fluid is not None:
            if hasattr(integ, "sync_models"):
                # P lives on the device (mjed.cuda.device_models): read back for the record,
                # after the step's clock stopped ((n + m) x 8 bytes a frame)
                integ.sync_models(fluid)
            self.p_max.append(float(np.abs(fluid.P).max()))
            if self.p_max[-1] >= self.best_P[0]:
                self.best_P = (self.p_max[-1], fluid.P.copy(), integ.x.copy())


def _timed_step(integ, synchronize):
    """One integrator step and its wall-clock and CPU seconds; the clock stops once
    ``synchronize()`` returns, when a GPU run's device has finished the step's work.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    report = integ.step()
    synchronize()
    return report, time.perf_counter() - t0, time.process_time() - c0


def simulate(
    kind: str,
    mesh,
    params: LiverParameters,
    fixed: np.ndarray,
    duration: float,
    *,
    force_field=numpy_force_field,
    writer=None,
    progress=None,
    dt: Optional[float] = None,
) -> LiverRun:
    """One run of ``kind`` over ``duration`` seconds (its record; ``to_dict()`` for JSON).

    dt overrides the model's step (the oscillation study). A step the integrator refuses
    (after its substeps) ends the run: ``error`` holds the message.
    """
    from mjed.darcy import cell_jacobians
    from mjed.errors import IntegrationError

    models, model_dt, fluid = _models(kind, mesh, params, fixed, force_field)
    dt = model_dt if dt is None else dt
    n_steps = max(1, int(round(duration / dt)))
    integ, where = run_integrator(
        force_field,
        mesh,
        models,
        params.density,
        dt=dt,
        gravity=params.gravity,
        fixed_nodes=fixed,
        rayleigh_mass=params.rayleigh_mass,
        rayleigh_stiffness=params.rayleigh_stiffness,
        solver=run_solver(force_field, params),
        max_halvings=params.max_halvings,
        allow_inverted=params.allow_inverted,
        max_volume_change=params.max_volume_change,
    )
    track = Trajectory()
    pressure = (lambda: None) if fluid is None else (lambda: fluid.P)
    if writer is not None:
        writer(0.0, integ.x, np.ones(mesh.n_cells), pressure())
    error, synchronize = None, device_synchronizer(force_field)
    for _ in range(n_steps):
        try:
            report, wall, cpu = _timed_step(integ, synchronize)
        except IntegrationError as exc:  # recorded, and the run stops here (the study fails)
            error = str(exc)
            break
        track.add(integ, report, mesh, fluid, wall, cpu)
        if writer is not None:
            writer(integ.t, integ.x, cell_jacobians(mesh, integ.x), pressure())
        if progress is not None:
            split = f", {report.substeps} substeps" if report.substeps > 1 else ""
            progress(
                f"{kind}: t = {integ.t:.2f} s, max |u| = {1e3 * track.amplitude[-1]:.1f} mm, "
                f"{report.cg_iterations} CG{split}"
            )
    solver = run_solver(force_field, params).label() + (f"; {where}" if where else "")
    return _run_record(kind, dt, n_steps, error, track, solver, force_field, fluid is not None)


def _run_record(
    kind: str,
    dt: float,
    n_steps: int,
    error: Optional[str],
    track: Trajectory,
    solver: str,
    force_field,
    porous: bool,
) -> LiverRun:
    """The record of one run (the derived figures, FPS included, are LiverRun's properties)."""
    label = getattr(
        force_field, "label", getattr(force_field, "__qualname__", type(force_field).__name__)
    )
    snapshot = None
    if porous and track.best_P[1] is not None:
        snapshot = PressureSnapshot(*track.best_P)
    return LiverRun(
        model=kind,
        dt=dt,
        steps_planned=n_steps,
        error=error,
        time=track.times,
        max_displacement=track.amplitude,
        cg_iterations=track.cg,
        substeps=track.substeps,
        retries=track.retries,
        inverted_cells=track.inverted,
        factorizations=track.factorizations,
        solver=solver,
        force_field=label,
        backend=getattr(force_field, "backend", "custom"),
        stepping_seconds=track.stepping,
        # Steps per CPU second of this process: what the run would reach with a core to itself
        # (the wall-clock FPS also counts the time other jobs on a shared machine take).
        cpu_fps=len(track.cg) / track.cpu if track.cpu > 0 else None,
        phase_seconds=dict(zip(PHASES, track.phases.tolist())),
        max_abs_pressure=track.p_max if porous else None,
        pressure_snapshot=snapshot,
    )


class _SeriesWriter:
    """A ParaView time series: one .vtu per step (meshio) under ``<stem>/`` and a .pvd index.

    (meshio 5.0's XDMF writer puts its .h5 file in the working directory, not beside the
    .xdmf, so the portable .pvd + .vtu form is used.)
    """

    def __init__(self, path: str, mesh):
        self.path = path
        self.mesh = mesh
        self.folder = os.path.splitext(path)[0]
        os.makedirs(self.folder, exist_ok=True)
        self.entries: List[tuple] = []

    def __call__(self, t: float, x: np.ndarray, J: np.ndarray, P) -> None:
        import meshio

        point_data = {"displacement": x - self.mesh.points}
        if P is not None:
            point_data["pressure"] = np.asarray(P, dtype=float)
        name = f"step_{len(self.entries):05d}.vtu"
        meshio.write(
            os.path.join(self.folder, name),
            meshio.Mesh(
                self.mesh.points,
                [("tetra", self.mesh.cells)],
                point_data=point_data,
                cell_data={"J": [J]},
            ),
        )
        self.entries.append((t, f"{os.path.basename(self.folder)}/{name}"))

    def close(self) -> None:
        rows = "\n".join(
            f'    <DataSet timestep="{t:.6g}" part="0" file="{f}"/>' for t, f in self.entries
        )
        with open(self.path, "w") as fh:
            fh.write(
                '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                f"{rows}\n  </Collection>\n</VTKFile>\n"
            )
