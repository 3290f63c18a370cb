"""The liver under gravity (paper, section 4.3; Fig. 1 right and Fig. 4).

A liver-shaped organ hangs from its vena cava and suspensory ligament and deforms under its
own weight, integrated by implicit Euler with CG, for three models:

* hyperelastic: Arruda-Boyce;
* visco-hyperelastic: the same with the paper's two-term Prony series (Fig. 3 values);
* visco-poro-hyperelastic: plus the porous solid U(J) (its own force field, in parallel, not
  relaxed by the Prony series) and the Darcy fluid pressure (drained at the fixed nodes).

Recorded: the maximum nodal displacement over time (Fig. 4), frames per second of each run
(one step = one frame; only the integrator steps are timed), the fluid pressure field
(Fig. 1 right), and a ParaView time series per run (.pvd + .vtu, displacement and pressure
on the nodes, J on the cells).

Parameters (``LiverParameters``; SI units). Shear: Arruda-Boyce mu = 2 kPa (N = 8, as SOFA),
about E = 6 kPa. The paper's DMA G0 = 770 Pa (and Mattei's E = 2.65 kPa) is softer, but with
it a 2.6 litre organ held only at the vena cava and ligament sags by more than 10 cm and the
linearised implicit step at 0.3 s meets negative curvature in CG (the run stops with an
IntegrationError); in the body the neighbouring organs carry much of that weight. Bulk:
k0 = 20 kPa (Poisson ratio about 0.4; the paper gives none). Density 1000 kg/m^3 (liver ~1050). Prony: alpha = (0.235, 0.333),
tau = (0.27, 0.03) s (paper Fig. 3). Porous: f_w = 0.5, K0 = 400 Pa, K_lim = 2200 Pa (paper
Fig. 1 right). Permeability: the paper's kappa = 20 m^4/(N s) gives a diffusivity
kappa K_lim = 4.4e4 m^2/s, which equilibrates a 10 cm organ in microseconds (its units are
presumably not SI metres); we use kappa = 5e-6 m^4/(N s), a diffusion time L^2/(kappa K_lim)
of about 1 s over 10 cm, and accept the paper's value through ``kappa``. Time steps: 0.3 s,
and 0.15 s with porosity, as in the paper. Rayleigh damping r_M = r_K = 0.1 (SOFA's liver
demo); with r_K = 0.01 the visco-hyperelastic run inverts cells at 0.3 s. Compressed-element
regularisation (paper, section 2.3) on.

Linear solver. CG to a relative residual of 1e-5 (one linearised step: its own error, O(dt^2)
in the positions, is far larger; the final amplitudes agree with a 1e-8 solve to about 1e-8 m),
preconditioned by a single-precision sparse LU factorisation of the step matrix that is kept
over the following steps and renewed after a solve that needs more than 20 iterations
(``preconditioner="factorized"``, ``factor_precision="single"``, see mjed.integrator): about 7
CG iterations per step instead of 200-250 with Jacobi, with 2-3 factorisations per 30-step run
(each one also certifies that the step matrix is positive definite, redone in double precision
before a step is refused). CG itself runs in double precision and still raises on
non-convergence and on negative curvature. ``preconditioner="jacobi"`` is the paper's / SOFA's plain choice;
``linear_solver="direct"`` (a factorisation every step) is a comparison point. The FPS table
names the solver of each run.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from comparisons.options import InputError
from comparisons.regions import relative_box, select_nodes

__all__ = ["LiverParameters", "MODELS", "PAPER_FPS", "default_fixed_specs", "run_liver"]

MODELS = ("hyperelastic", "visco-hyperelastic", "visco-poro-hyperelastic")
#: The paper's frame rates (2010 laptop, Core Duo 2.8 GHz), and the real-time target.
PAPER_FPS = {"hyperelastic": 7.5, "visco-hyperelastic": 7.0, "visco-poro-hyperelastic": 6.0}
TARGET_FPS = 25.0
#: Relative L2 pressure error allowed in the Terzaghi check (verification.md, section 8).
TERZAGHI_TOL = 1e-2


@dataclass(frozen=True)
class LiverParameters:
    """The liver model and the scenario (see the module docstring for the sources)."""

    mu: float = 2000.0
    k0: float = 20000.0
    N: float = 8.0
    density: float = 1000.0
    prony_alphas: tuple = (0.235, 0.333)
    prony_taus: tuple = (0.27, 0.03)
    f_w: float = 0.5
    K0: float = 400.0
    K_lim: float = 2200.0
    kappa: float = 5e-6
    dt: float = 0.3
    dt_porous: float = 0.15
    rayleigh_mass: float = 0.1
    rayleigh_stiffness: float = 0.1
    cg_tol: float = 1e-5
    linear_solver: str = "cg"
    preconditioner: str = "factorized"
    refactor_iterations: int = 20
    factor_precision: str = "single"
    gravity: tuple = (0.0, 0.0, -9.81)
    regularize: bool = True

    def __post_init__(self):
        for name in ("mu", "k0", "N", "density", "K0", "K_lim", "dt", "dt_porous", "cg_tol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"LiverParameters: parameter {name} must be finite and > 0, got {v!r}")
        for name in ("kappa", "rayleigh_mass", "rayleigh_stiffness"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"LiverParameters: parameter {name} must be finite and >= 0, got {v!r}")
        from mjed.integrator import FACTOR_PRECISIONS, LINEAR_SOLVERS, PRECONDITIONERS

        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValueError(f"LiverParameters: parameter linear_solver must be one of {LINEAR_SOLVERS}, got {self.linear_solver!r}")
        if self.preconditioner not in PRECONDITIONERS:
            raise ValueError(f"LiverParameters: parameter preconditioner must be one of {PRECONDITIONERS}, got {self.preconditioner!r}")
        if self.factor_precision not in FACTOR_PRECISIONS:
            raise ValueError(f"LiverParameters: parameter factor_precision must be one of {FACTOR_PRECISIONS}, "
                             f"got {self.factor_precision!r}")
        r = self.refactor_iterations
        if isinstance(r, bool) or not isinstance(r, int) or r < 1:
            raise ValueError(f"LiverParameters: parameter refactor_iterations must be an integer >= 1, got {r!r}")


def solver_label(params: LiverParameters) -> str:
    """How the linear system of each step was solved, for the FPS table."""
    if params.linear_solver == "direct":
        return "direct sparse LU (SuperLU), every step"
    if params.preconditioner == "factorized":
        return (f"CG, kept {params.factor_precision}-precision sparse LU preconditioner (renewed after "
                f"> {params.refactor_iterations} iterations), rtol {params.cg_tol:g}")
    return f"CG, {params.preconditioner} preconditioner, rtol {params.cg_tol:g}"


def default_fixed_specs(points: np.ndarray) -> List[str]:
    """Vena cava and suspensory ligament, as fractions of the mesh's bounding box.

    Vena cava (with the bare area around it, where the liver lies against the diaphragm): a
    block on the posterior-superior side between the lobes (x in 25-75 %, y in the back 40 %,
    z above 35 %). Suspensory ligament: a strip on top between the lobes (x in 30-55 %, z in
    the top 20 %). Axes as in meshes/liver.py (x left to right, y anterior to posterior, z up).
    """
    return [
        relative_box(points, (0.25, 0.60, 0.35), (0.75, 1.0, 1.0)),
        relative_box(points, (0.30, 0.0, 0.80), (0.55, 1.0, 1.0)),
    ]


def _load_mesh(mesh_spec):
    import meshes
    import mjed

    if isinstance(mesh_spec, tuple):
        points, cells, label = (*mesh_spec, "given")[:3]
    else:
        try:
            points, cells, label = meshes.resolve(mesh_spec)
        except (ValueError, OSError) as exc:
            raise InputError(str(exc)) from None
    cells = np.asarray(cells)
    if cells.ndim != 2 or len(cells) == 0:
        raise InputError(f"mesh {label}: no volume (tetrahedral) cells")
    try:
        return mjed.TetMesh(points, cells), label
    except ValueError as exc:
        raise InputError(f"mesh {label}: {exc}") from None


def _models(kind: str, mesh, params: LiverParameters, fixed: np.ndarray):
    """Force models, the time step and the fluid model (or None) of one run."""
    import mjed
    from mjed.darcy import DarcyParameters, FluidPressureForce
    from mjed.materials import ArrudaBoyce
    from mjed.porous import PorousVolume
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    solid = mjed.HyperelasticForceField(mesh, ArrudaBoyce(mu=params.mu, k0=params.k0, N=params.N), regularize=params.regularize)
    if kind == "hyperelastic":
        return [solid], params.dt, None
    visco = ViscoHyperelasticForceField(solid, prony=Prony(params.prony_alphas, params.prony_taus))
    if kind == "visco-hyperelastic":
        return [visco], params.dt, None
    # The porous solid U(J) and the fluid pressure are one volumetric model (sigma_p = sigma - P),
    # in parallel with the visco-hyperelastic network, so the Prony series does not relax them.
    law = PorousVolume(params.f_w, params.K0, params.K_lim)
    fluid = FluidPressureForce(mesh, DarcyParameters(params.K_lim, params.kappa), solid=law, drained_nodes=fixed)
    return [visco, fluid], params.dt_porous, fluid


def _simulate(kind, mesh, params, fixed, duration, writer=None, progress=None) -> Dict:
    from mjed.darcy import cell_jacobians
    from mjed.errors import IntegrationError
    from mjed.integrator import ImplicitEuler

    models, dt, fluid = _models(kind, mesh, params, fixed)
    n_steps = max(1, int(round(duration / dt)))
    integ = ImplicitEuler(mesh, models, params.density, dt=dt, gravity=params.gravity, fixed_nodes=fixed,
                          rayleigh_mass=params.rayleigh_mass, rayleigh_stiffness=params.rayleigh_stiffness, cg_tol=params.cg_tol,
                          linear_solver=params.linear_solver, preconditioner=params.preconditioner,
                          refactor_iterations=params.refactor_iterations, factor_precision=params.factor_precision)
    times, amplitude, cg, factorizations, p_max = [0.0], [0.0], [], 0, [0.0]
    stepping = cpu = 0.0  # wall-clock and CPU seconds spent in the integrator's steps
    best_P = (0.0, None, None)  # (max |P|, P, x) for the Fig. 1 picture
    if writer is not None:
        writer(0.0, integ.x, np.ones(mesh.n_cells), None if fluid is None else fluid.P)
    error = None
    for _ in range(n_steps):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            report = integ.step()
        except IntegrationError as exc:  # recorded, and the run stops here (the CLI exits with 1)
            error = str(exc)
            break
        stepping += time.perf_counter() - t0
        cpu += time.process_time() - c0
        u = integ.x - mesh.points
        times.append(integ.t)
        amplitude.append(float(np.linalg.norm(u, axis=1).max()))
        cg.append(report.cg_iterations)
        factorizations += report.factorizations
        if fluid is not None:
            p_max.append(float(np.abs(fluid.P).max()))
            if p_max[-1] >= best_P[0]:
                best_P = (p_max[-1], fluid.P.copy(), integ.x.copy())
        if writer is not None:
            writer(integ.t, integ.x, cell_jacobians(mesh, integ.x), None if fluid is None else fluid.P)
        if progress is not None:
            progress(f"{kind}: t = {integ.t:.2f} s, max |u| = {1e3 * amplitude[-1]:.1f} mm, {report.cg_iterations} CG")
    done = len(cg)
    out = {
        "model": kind,
        "dt": dt,
        "steps": done,
        "steps_planned": n_steps,
        "error": error,
        "time": times,
        "max_displacement": amplitude,
        "final_max_displacement": amplitude[-1],
        "peak_max_displacement": max(amplitude),
        "cg_iterations_mean": float(np.mean(cg)) if cg else None,
        "cg_iterations": cg,
        "factorizations": factorizations,
        "solver": solver_label(params),
        "stepping_seconds": stepping,
        "fps": done / stepping if stepping > 0 else None,
        # Steps per CPU second of this process: what the run would reach with a core to itself
        # (the wall-clock FPS above also counts the time other jobs on a shared machine take).
        "cpu_fps": done / cpu if cpu > 0 else None,
        "realtime_factor": done * dt / stepping if stepping > 0 else None,  # simulated s per wall s
        "paper_fps": PAPER_FPS[kind],
    }
    if fluid is not None:
        out["max_abs_pressure"] = p_max
        out["_pressure_snapshot"] = best_P
    return out


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
        meshio.write(os.path.join(self.folder, name),
                     meshio.Mesh(self.mesh.points, [("tetra", self.mesh.cells)], point_data=point_data, cell_data={"J": [J]}))
        self.entries.append((t, f"{os.path.basename(self.folder)}/{name}"))

    def close(self) -> None:
        rows = "\n".join(f'    <DataSet timestep="{t:.6g}" part="0" file="{f}"/>' for t, f in self.entries)
        with open(self.path, "w") as fh:
            fh.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                     f"{rows}\n  </Collection>\n</VTKFile>\n")


def run_liver(
    mesh="liver",
    *,
    fixed: Optional[Sequence[str]] = None,
    steps: Optional[int] = None,
    out: str = os.path.join("reports", "liver"),
    json_path: Optional[str] = None,
    quick: bool = False,
    params: LiverParameters = LiverParameters(),
    models: Sequence[str] = MODELS,
    series: bool = True,
    progress: Optional[Callable[[str], None]] = None,
) -> Dict:
    """Run the three liver simulations and write the figures; returns a JSON-serialisable dict.

    Args:
        mesh: a catalog name, a mesh file path, or (points, cells).
        fixed: region specs (see comparisons.regions); default vena cava + ligament.
        steps: steps of the 0.3 s runs (default 30, quick 6); the porous run covers the same
            simulated time at its own step.
        out: output directory (figures, .pvd + .vtu series).
        quick: the coarse mesh (when ``mesh`` is the default) and few steps.
        models: which of MODELS to run.
        series: write the ParaView time series.

    Raises:
        InputError: unknown mesh, a mesh without volume cells, a bad region spec, an empty
            fixed set, bad step count.

    A run that fails (an IntegrationError: CG negative curvature, inverted cells...) stops
    there; its "error" holds the message and "passed" is False.
    """
    if quick and mesh == "liver":
        mesh = "liver-coarse"
    tet_mesh, label = _load_mesh(mesh)
    specs = list(fixed) if fixed else default_fixed_specs(tet_mesh.points)
    fixed_nodes = select_nodes(specs, tet_mesh.points)
    if steps is None:
        steps = 6 if quick else 30
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise InputError(f"--steps must be a positive integer, got {steps!r}")
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        raise InputError(f"unknown liver model(s) {unknown}; known: {', '.join(MODELS)}")
    duration = int(steps) * params.dt
    os.makedirs(out, exist_ok=True)

    runs, figures, series_paths = [], [], []
    for kind in models:
        writer = None
        if series:
            writer = _SeriesWriter(os.path.join(out, f"liver_{kind}.pvd"), tet_mesh)
            series_paths.append(writer.path)
        try:
            runs.append(_simulate(kind, tet_mesh, params, fixed_nodes, duration, writer, progress))
        finally:
            if writer is not None:
                writer.close()

    from comparisons.liver_figures import plot_amplitudes, plot_porous_stress, plot_pressure

    from comparisons.terzaghi import run_terzaghi

    # The pressure solver's own check, beside the scenario that uses it.
    terzaghi = run_terzaghi(dt=0.004, figure=os.path.join(out, "terzaghi.png"))
    figures += terzaghi["figures"]
    figures.append(plot_porous_stress(os.path.join(out, "fig1_left_porous_stress.png"), params))
    figures.append(plot_amplitudes(os.path.join(out, "fig4_max_displacement.png"), runs, label))
    for r in runs:
        snap = r.pop("_pressure_snapshot", None)
        if snap is not None and snap[1] is not None:
            figures.append(plot_pressure(os.path.join(out, "fig1_right_pressure.png"), tet_mesh, snap[2], snap[1], fixed_nodes))
    result = {
        "mesh": label,
        "n_nodes": tet_mesh.n_nodes,
        "n_cells": tet_mesh.n_cells,
        "fixed_regions": specs,
        "n_fixed": int(len(fixed_nodes)),
        "quick": bool(quick),
        "duration": duration,
        "parameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(params).items()},
        "runs": runs,
        "fps_table": [{"model": r["model"], "dt": r["dt"], "fps": r["fps"], "cpu_fps": r["cpu_fps"], "paper_fps": r["paper_fps"],
                       "target_fps": TARGET_FPS, "meets_target": bool(r["fps"] is not None and r["fps"] >= TARGET_FPS),
                       "solver": r["solver"], "cg_iterations_mean": r["cg_iterations_mean"],
                       "factorizations": r["factorizations"]}
                      for r in runs],
        "terzaghi": terzaghi,
        "passed": all(r["error"] is None for r in runs) and max(t["relative_l2_error"] for t in terzaghi["times"]) <= TERZAGHI_TOL,
        "figures": figures,
        "series": series_paths,
    }
    if json_path:
        from comparisons.options import write_json

        write_json(json_path, result)
    return result
