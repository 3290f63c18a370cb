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

The user's organ (``comparisons.liver.organ``): any mesh file the readers take (gmsh 1.0 to 4.1,
VTK, Medit, Abaqus), its length unit (``--units``/``--scale``: positions are converted to metres,
region specs stay in the file's units), its node numbering (``--fixed nodes:FILE`` lists node ids as
the file numbers them), gravity in any direction, the time step, the material (any of
mjed.materials, by parameters or a SOFA ParameterSet), density and Rayleigh damping.

Steps that fail (inverted cells, CG on negative curvature or its iteration cap) are retried in
substeps by the integrator (down to dt/16 by default), reported per step (``substeps``,
``retries``) in the JSON and the FPS table; with ``allow_inverted`` and a material whose
energy stays finite at J <= 0 (see mjed.inversion), inverted cells are accepted and counted.

Parameters (``LiverParameters``; SI units). Shear: Arruda-Boyce mu = 2 kPa (N = 8, as SOFA),
about E = 6 kPa. The paper's DMA G0 = 770 Pa (and Mattei's E = 2.65 kPa) is softer, but with
it a 2.6 litre organ held only at the vena cava and ligament sags by more than 10 cm and the
linearised implicit step at 0.3 s meets negative curvature in CG (the run stops with an
IntegrationError); in the body the neighbouring organs carry much of that weight. Bulk:
k0 = 20 kPa (Poisson ratio about 0.4; the paper gives none). Density 1000 kg/m^3 (liver ~1050).
Prony: alpha = (0.235, 0.333),
tau = (0.27, 0.03) s (paper Fig. 3). Porous: f_w = 0.5, K0 = 400 Pa, K_lim = 2200 Pa (paper
Fig. 1 right). Permeability: the paper's kappa = 20 m^4/(N s) gives a diffusivity
kappa K_lim = 4.4e4 m^2/s, which equilibrates a 10 cm organ in microseconds (its units are
presumably not SI metres); we use kappa = 5e-6 m^4/(N s), a diffusion time L^2/(kappa K_lim)
of about 1 s over 10 cm, and accept the paper's value through ``kappa``. Time steps: 0.3 s,
and 0.15 s with porosity, as in the paper. Rayleigh damping r_M = r_K = 0.1 (SOFA's liver
demo); with r_K = 0.01 the visco-hyperelastic run inverts cells at 0.3 s. Compressed-element
regularisation (paper, section 2.3) on.

Linear solver (``LiverParameters.solver``, a mjed.solvers.LinearSolverOptions). CG to a relative
residual of 1e-5 (one linearised step: its own error, O(dt^2)
in the positions, is far larger; the final amplitudes agree with a 1e-8 solve to about 1e-8 m),
preconditioned by a single-precision sparse LU factorisation of the step matrix that is kept
over the following steps and renewed after a solve that needs more than 20 iterations
(``LinearSolverOptions(preconditioner="factorized", factor_precision="single")``, see
mjed.integrator): about 7
CG iterations per step instead of 200-250 with Jacobi, with 2-3 factorisations per 30-step run
(each one also certifies that the step matrix is positive definite, redone in double precision
before a step is refused). CG itself runs in double precision and still raises on
non-convergence and on negative curvature. ``preconditioner="jacobi"`` is the paper's / SOFA's plain
choice;
``solver="direct"`` (a factorisation every step) is a comparison point. The FPS table
names the solver of each run.

Backends. The hyperelastic force field comes from a factory (mesh, material, regularize=...,
allow_inverted=... -> a model with force_and_stiffness); the study runs every model once per
factory (``backend_force_field``: the NumPy engine and the compiled Numba kernel of
mjed.make_force_field, by default both when Numba is installed). The compiled kernel is
compiled, or loaded from Numba's cache, before the clock starts. The FPS table and the step
split name the backend of each run; the runs of the second backend are checked against the
first (the same trajectory up to the linear solver's tolerance), and the figures of the
trajectory, the pressure and the oscillation study come from the first.
"""

from __future__ import annotations

import dataclasses
import os
import shlex
import time
import warnings
from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from common.options import InputError
from common.result import StudyResult
from comparisons.liver.organ import Organ, check_supports, fixed_nodes, load_organ, scale_of
from mjed.errors import MeshWarning

__all__ = [
    "LiverParameters",
    "MODELS",
    "PAPER_FPS",
    "TARGET_FPS",
    "COMPILED_TARGET_FPS",
    "PAPER_HYPERELASTIC_SHARE",
    "BACKEND_AGREEMENT_TOL",
    "backend_force_field",
    "default_fixed_specs",
    "run_liver",
    "liver_study",
    "numpy_force_field",
    "LIVER_SOLVER",
]
from comparisons.liver.oscillation_records import OscillationData
from comparisons.liver.records import (
    BackendAgreement,
    LiverData,
    LiverRun,
    StepSplit,
)
from comparisons.liver.setup import (
    BACKEND_AGREEMENT_TOL,
    BACKENDS,
    COMPILED_TARGET_FPS,
    LIVER_SOLVER,
    MODELS,
    PAPER_FPS,
    PAPER_HYPERELASTIC_SHARE,
    TARGET_FPS,
    TERZAGHI_TOL,
    LiverParameters,
    LiverStudyOptions,
    _backend_factories,
    backend_force_field,
    default_fixed_specs,
    numpy_force_field,
)
from comparisons.liver.simulation import PHASES, _SeriesWriter, simulate


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
    scale: float = 1.0,
    fix_orientation: bool = False,
    force_fields: Sequence[Callable] = (numpy_force_field,),
    organ: Optional[Organ] = None,
    allow_disconnected: bool = False,
) -> LiverData:
    """Run the liver simulations and write the figures; returns their LiverData.

    mesh: a catalog name, a mesh file path, or (points, cells), or ``organ`` already loaded
    (then mesh, scale and fix_orientation are not used); fixed: region specs (see
    comparisons.liver.regions; in the mesh file's units and numbering), default vena cava +
    ligament; steps: of the dt runs (default 30, quick 6; the porous run covers the same
    time); out: figures and the .pvd + .vtu series; scale: metres per mesh unit;
    force_fields: factories of the hyperelastic force field (see backend_force_field), every
    model runs once per factory and the figures show the first one's runs; allow_disconnected:
    accept a mesh in several parts each with a fixed node (warned). Raises InputError
    on bad input (see liver_setup). A run the integrator stops (a step refused after its
    substeps) ends there: its ``error`` holds the message and ``passed`` is False.
    """
    setup = liver_setup(
        mesh,
        fixed=fixed,
        steps=steps,
        quick=quick,
        params=params,
        models=models,
        force_fields=force_fields,
        organ=organ,
        scale=scale,
        fix_orientation=fix_orientation,
        allow_disconnected=allow_disconnected,
    )
    os.makedirs(out, exist_ok=True)
    runs, series_paths = _run_models(setup, params, out, series, progress)
    figures, terzaghi, split = _run_figures(setup, params, runs, out)
    result = _liver_record(setup, params, runs, figures, terzaghi, split, series_paths)
    if json_path:
        from common.options import write_json

        write_json(json_path, result.to_dict())
    return result


@dataclass(frozen=True)
class LiverSetup:
    """A validated liver run: the organ, its supports, how long and what to run."""

    organ: Organ
    specs: List[str]
    fixed: np.ndarray
    steps: int
    duration: float
    models: Sequence[str]
    force_fields: Sequence[Callable]
    quick: bool
    mesh_warnings: Tuple[str, ...] = ()


def liver_setup(
    mesh="liver",
    *,
    fixed=None,
    steps=None,
    quick=False,
    params: LiverParameters = LiverParameters(),
    models: Sequence[str] = MODELS,
    force_fields: Sequence[Callable] = (numpy_force_field,),
    organ: Optional[Organ] = None,
    scale: float = 1.0,
    fix_orientation: bool = False,
    allow_disconnected: bool = False,
) -> LiverSetup:
    """Check every input of a liver run and load the organ (unless given); InputError if bad.

    The supports are checked here, before any run (comparisons.liver.organ.check_supports): a part
    of the mesh that nothing holds would fall freely and the run would still complete.
    """
    if quick and mesh == "liver":
        mesh = "liver-coarse"
    if organ is None:
        organ = load_organ(mesh, scale=scale, fix_orientation=fix_orientation)
    if not fixed:
        g = np.asarray(params.gravity)
        if not (g[0] == 0 and g[1] == 0 and g[2] < 0):
            raise InputError(
                "the default fixed regions (vena cava, ligament) assume a z-up organ; with "
                f"gravity {list(params.gravity)} give the supports with --fixed (box:, sphere:, "
                "nodes:FILE)"
            )
    specs = list(fixed) if fixed else default_fixed_specs(organ.file_points)
    nodes = fixed_nodes(organ, specs)
    mesh_warnings = check_supports(organ, nodes, allow_disconnected=allow_disconnected)
    for text in mesh_warnings:
        warnings.warn(text, MeshWarning, stacklevel=2)
    if steps is None:
        steps = 6 if quick else 30
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise InputError(f"--steps must be a positive integer, got {steps!r}")
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        raise InputError(f"unknown liver model(s) {unknown}; known: {', '.join(MODELS)}")
    if not force_fields:
        raise InputError("give at least one force field (backend)")
    return LiverSetup(
        organ,
        specs,
        nodes,
        int(steps),
        int(steps) * params.dt,
        tuple(models),
        tuple(force_fields),
        bool(quick),
        tuple(mesh_warnings),
    )


def _run_models(setup: LiverSetup, params: LiverParameters, out: str, series: bool, progress):
    """Every model once per force field; the first field's runs also write the series."""
    runs, series_paths = [], []
    mesh = setup.organ.mesh
    for index, force_field in enumerate(setup.force_fields):
        for kind in setup.models:
            writer = None
            if series and index == 0:  # other backends are checked equal, not written again
                writer = _SeriesWriter(os.path.join(out, f"liver_{kind}.pvd"), mesh)
                series_paths.append(writer.path)
            try:
                runs.append(
                    simulate(
                        kind,
                        mesh,
                        params,
                        setup.fixed,
                        setup.duration,
                        force_field=force_field,
                        writer=writer,
                        progress=progress,
                    )
                )
            finally:
                if writer is not None:
                    writer.close()
    return runs, series_paths


def _run_figures(setup: LiverSetup, params: LiverParameters, runs: List[LiverRun], out: str):
    """The Terzaghi check and the run's figures (the first backend's runs are drawn)."""
    from comparisons.liver.figures import (
        plot_amplitudes,
        plot_porous_stress,
        plot_pressure,
        plot_step_split,
    )
    from comparisons.liver.terzaghi import run_terzaghi

    first = [r for r in runs if r.backend == runs[0].backend]
    # The pressure solver's own check, beside the scenario that uses it.
    terzaghi = run_terzaghi(dt=0.004, figure=os.path.join(out, "terzaghi.png"))
    figures = list(terzaghi.figures)
    figures.append(plot_porous_stress(os.path.join(out, "fig1_left_porous_stress.png"), params))
    figures.append(
        plot_amplitudes(os.path.join(out, "fig4_max_displacement.png"), first, setup.organ.label)
    )
    split = step_split(runs)
    if split:
        figures.append(
            plot_step_split(
                os.path.join(out, "step_time_split.png"), split, PAPER_HYPERELASTIC_SHARE
            )
        )
    for r in first:
        snap = r.pressure_snapshot
        if snap is not None:
            figures.append(
                plot_pressure(
                    os.path.join(out, "fig1_right_pressure.png"),
                    setup.organ.mesh,
                    snap.positions,
                    snap.pressure,
                    setup.fixed,
                )
            )
    return figures, terzaghi, split


def _liver_record(
    setup: LiverSetup, params: LiverParameters, runs, figures, terzaghi, split, series_paths
) -> LiverData:
    """The record of a liver run (its to_dict() goes to results.json and --json)."""
    organ, nodes = setup.organ, setup.fixed
    return LiverData(
        mesh=organ.label,
        mesh_description=organ.describe(),
        n_nodes=organ.mesh.n_nodes,
        n_cells=organ.mesh.n_cells,
        scale=organ.scale,
        numbering=organ.numbering,
        reoriented_cells=organ.reoriented,
        unused_nodes=int(len(organ.unused_nodes)),
        mesh_warnings=setup.mesh_warnings,
        fixed_regions=setup.specs,
        n_fixed=int(len(nodes)),
        fixed_node_ids=organ.node_ids[nodes].tolist() if len(nodes) <= 50 else None,
        quick=setup.quick,
        duration=setup.duration,
        parameters=params.to_dict(),
        runs=runs,
        step_split=split,
        backend_agreement=backend_agreement(runs),
        terzaghi=terzaghi,
        figures=figures,
        series=series_paths,
    )


def step_split(runs: Sequence[LiverRun]) -> List[StepSplit]:
    """Share of each phase in the steps of each completed run (the paper's Fig. 2, left)."""
    rows = []
    for r in runs:
        seconds = np.array([r.phase_seconds[p] for p in PHASES])
        total = seconds.sum()
        if r.steps == 0 or total <= 0:
            continue
        rows.append(
            StepSplit(
                model=r.model,
                backend=r.backend,
                ms_per_step=1e3 * total / r.steps,
                shares=dict(zip(PHASES, (seconds / total).tolist())),
            )
        )
    return rows


def backend_agreement(runs: Sequence[LiverRun]) -> List[BackendAgreement]:
    """Each later backend's run against the first backend's run of the same model: the largest
    difference of the maximum-displacement curves relative to the first's peak (None when the
    two did not take the same steps).
    """
    if not runs:
        return []
    reference = {r.model: r for r in runs if r.backend == runs[0].backend}
    rows = []
    for r in runs:
        ref = reference.get(r.model)
        if ref is None or r.backend == ref.backend:
            continue
        same = (
            r.error is None
            and ref.error is None
            and len(r.max_displacement) == len(ref.max_displacement)
        )
        diff = None
        if same:
            a, b = np.asarray(r.max_displacement), np.asarray(ref.max_displacement)
            diff = float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))
        rows.append(BackendAgreement(r.model, r.backend, ref.backend, diff))
    return rows


# ----------------------------------------------------------------------------- the study
KEY = "liver"
TITLE = "The liver under gravity (paper Fig. 1, Fig. 2 left and Fig. 4)"
_CAPTIONS = {
    "fig1_left_porous_stress": "Fig. 1 left: porous volumetric stress sigma(J) before and after "
    "the tangent substitution below J0",
    "fig1_right_pressure": "Fig. 1 right: fluid pressure in the liver at the time of its largest "
    "magnitude",
    "fig4_max_displacement": "Fig. 4 (this study's scenario, Rayleigh damping as SOFA's liver "
    "demo): maximum displacement over time for the three models; ringed steps were taken in "
    "substeps",
    "fig4_oscillations": "Fig. 4 as the paper describes it: the three models without Rayleigh "
    "damping, time steps from the paper's 0.3 s down; backward Euler's own damping grows with dt",
    "fig4_decay_rate": "Decay rate of the oscillation against dt, with backward Euler's prediction "
    "on the frequency measured at the smallest dt",
    "step_time_split": "Where a step's time goes (paper Fig. 2 left: the hyperelastic force and "
    "stiffness take about 60 %)",
    "terzaghi": "Terzaghi consolidation: the pressure solver against the series solution",
}


def liver_command(opts: LiverStudyOptions) -> str:
    """The mjed-verify command that reproduces a liver study with these options.

    Options the command line cannot express (a Python-only parameter) are named after it.
    """
    parts, python_only = ["mjed-verify", "liver"], []
    if opts.quick:
        parts.append("--quick")
    if isinstance(opts.mesh, tuple):
        python_only.append("mesh given as arrays")
    elif opts.mesh != "liver":
        parts += ["--mesh", str(opts.mesh)]
    if opts.units is not None:
        parts += ["--units", opts.units]
    if opts.scale is not None:
        parts += ["--scale", f"{opts.scale:g}"]
    if opts.fix_orientation:
        parts.append("--fix-orientation")
    if opts.allow_disconnected:
        parts.append("--allow-disconnected")
    for spec in opts.fixed or ():
        parts += ["--fixed", spec]
    if opts.steps is not None:
        parts += ["--steps", str(opts.steps)]
    if list(opts.models) != list(MODELS):
        parts += ["--models", ",".join(opts.models)]
    if opts.force_fields is not None:
        python_only.append("force fields given as factories")
    elif list(opts.backends) != list(BACKENDS):
        parts += ["--backends", ",".join(opts.backends)]
    words, unexpressed = _parameter_words(opts.params)
    parts += words + _switch_words(opts) + ["--out", opts.out_dir]
    python_only += unexpressed
    text = " ".join(_quote(p) for p in parts)
    return text + (f"  (plus, from Python only: {'; '.join(python_only)})" if python_only else "")


def _switch_words(opts: LiverStudyOptions) -> List[str]:
    """The on/off options that differ from the defaults."""
    return [
        word
        for on, word in (
            (not opts.oscillation, "--no-oscillation"),
            (opts.full_oscillation, "--full-oscillation"),
            (not opts.series, "--no-series"),
        )
        if on
    ]


_PARAMETER_FLAGS = {
    "dt": "--dt",
    "dt_porous": "--dt-porous",
    "density": "--density",
    "rayleigh_mass": "--rayleigh-mass",
    "rayleigh_stiffness": "--rayleigh-stiffness",
    "kappa": "--kappa",
    "max_halvings": "--max-halvings",
    "max_volume_change": "--max-volume-change",
}


def _parameter_words(params: LiverParameters):
    """The command-line words for the parameters that differ from the defaults, and the ones
    only Python can set.
    """
    base, parts, python_only = LiverParameters(), [], []
    if params.material != base.material:
        parts += ["--material", type(params.material).__name__]
        for f in (fld.name for fld in dataclasses.fields(params.material)):
            v = getattr(params.material, f)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                parts += ["--param", f"{f}={v!r}"]
            elif v is not None and not isinstance(v, str):
                python_only.append(f"material {f}")
    for name, flag in _PARAMETER_FLAGS.items():
        if getattr(params, name) != getattr(base, name):
            parts += [flag, repr(getattr(params, name))]
    if params.gravity != base.gravity:
        parts += ["--gravity", ",".join(f"{g:g}" for g in params.gravity)]
    if params.allow_inverted:
        parts.append("--allow-inverted")
    solver_flag = {
        dataclasses.replace(LIVER_SOLVER, preconditioner=p): p
        for p in ("jacobi", "block-jacobi", "factorized")
    }
    solver_flag[dataclasses.replace(LIVER_SOLVER, solver="direct")] = "direct"
    if params.solver != LIVER_SOLVER:
        if params.solver in solver_flag:
            parts += ["--solver", solver_flag[params.solver]]
        else:
            python_only.append(f"solver {params.solver}")
    for name in ("prony_alphas", "prony_taus", "f_w", "K0", "K_lim", "regularize"):
        if getattr(params, name) != getattr(base, name):
            python_only.append(f"{name}={getattr(params, name)!r}")
    return parts, python_only


def _quote(text: str) -> str:
    return shlex.quote(text)


def liver_study(*, progress: Optional[Callable[[str], None]] = None, **options) -> StudyResult:
    """The liver study as a typed result: the runs, FPS, substeps, the step split, the
    oscillation study (Fig. 4 as the paper describes it) and the Terzaghi check.

    options: the fields of :class:`LiverStudyOptions`. Checks: Terzaghi (1 %), each run
    completing its steps, FPS >= 25 and >= 60 compiled (targets), each later backend's
    trajectory equal to the first's (BACKEND_AGREEMENT_TOL). A backend that cannot be built
    here is left out and said so. The oscillation study is reported, not held to a threshold:
    on the built-in organ it runs on the coarse liver over 3 s, or with ``full_oscillation``
    on the paper-size liver over 5 s down to dt 0.003 s; a user's mesh is used as given.
    Raises InputError on bad input, before any run.
    """
    opts = LiverStudyOptions(**options)
    clock = time.perf_counter()
    command = liver_command(opts)
    force_fields, not_covered = opts.force_fields, []
    if force_fields is None:
        force_fields, not_covered = _backend_factories(opts.backends)
    not_covered += _left_out(opts.quick, opts.models, opts.oscillation)
    mesh = "liver-coarse" if opts.quick and opts.mesh == "liver" else opts.mesh
    # The organ is read and validated once here; every run below uses this one.
    organ = load_organ(
        mesh, scale=scale_of(opts.units, opts.scale), fix_orientation=opts.fix_orientation
    )
    data = run_liver(
        fixed=opts.fixed,
        steps=opts.steps,
        out=opts.out_dir,
        quick=opts.quick,
        params=opts.params,
        models=opts.models,
        series=opts.series,
        progress=progress,
        force_fields=force_fields,
        organ=organ,
        allow_disconnected=opts.allow_disconnected,
    )
    osc = None
    if opts.oscillation:
        osc = _oscillation(organ, opts, force_fields[0], progress)
        data = dataclasses.replace(data, oscillation=osc, figures=data.figures + osc.figures)
    protocol = _liver_protocol(data, osc, opts.full)
    data = dataclasses.replace(data, protocol=protocol)
    if opts.json_path:
        from common.options import write_json

        write_json(opts.json_path, data.to_dict())
    return StudyResult.from_checks(
        KEY,
        TITLE,
        _liver_checks(data),
        headline=_liver_headline(data, osc, opts.models),
        command=command,
        not_covered=not_covered,
        protocol=protocol,
        data=data.to_dict(),
        blocks=_liver_blocks(data, opts.params, osc, opts.relative_to),
        seconds=time.perf_counter() - clock,
    )


def _left_out(quick: bool, models: Sequence[str], oscillation: bool) -> List[str]:
    """What a liver study with these options does not cover, in words."""
    out = []
    if quick:
        out.append(
            "quick: coarse liver and 6 steps instead of the paper-size liver and 30 steps; "
            "oscillation study at dt 0.3, 0.1, 0.03 s over 1.5 s"
        )
    skipped = [m for m in MODELS if m not in models]
    if skipped:
        out.append(f"models not run: {', '.join(skipped)}")
    if not oscillation:
        out.append("oscillation study not run (--no-oscillation)")
    return out


def _oscillation(organ: Organ, opts: LiverStudyOptions, force_field, progress) -> OscillationData:
    """Fig. 4 as the paper describes it: the models without damping, over several time steps.

    The built-in organ's study runs on the coarse liver by default (time), the paper-size one
    when ``full``; a user's organ is always the user's.
    """
    from comparisons.liver.oscillation import OSCILLATION_DTS, run_oscillations

    if organ.label in ("liver", "liver-coarse"):
        wanted = "liver" if opts.full else "liver-coarse"
        osc_organ = organ if organ.label == wanted else load_organ(wanted)
    else:
        osc_organ = organ
    if opts.full:
        dts, duration = (*OSCILLATION_DTS, 0.003), 5.0
    else:
        dts, duration = (OSCILLATION_DTS[:3], 1.5) if opts.quick else (OSCILLATION_DTS, 3.0)
    specs = (
        list(opts.fixed)
        if opts.fixed and osc_organ is organ
        else default_fixed_specs(osc_organ.file_points)
    )
    return run_oscillations(
        osc_organ,
        fixed_nodes(osc_organ, specs),
        opts.params,
        dts=dts,
        duration=duration,
        models=opts.models,
        force_field=force_field,
        out_dir=opts.out_dir,
        progress=progress,
    )


def _liver_checks(data: LiverData) -> List:
    """Terzaghi's tolerance, every run completing, the FPS targets and backend agreement."""
    from common.result import Check

    checks = [
        Check(
            "Terzaghi consolidation: relative L2 pressure error, worst time factor",
            data.terzaghi_error,
            TERZAGHI_TOL,
        )
    ]
    runs = data.runs
    checks += [
        Check(
            f"{r.model} run completes its {r.steps_planned} steps of {r.dt:g} s (fraction done)",
            r.steps / r.steps_planned,
            1.0,
            ">=",
            note=r.error or "",
        )
        for r in runs
    ]
    checks += [
        Check(
            f"{r.model} frames per second on {data.mesh} ({r.force_field})",
            r.fps,
            TARGET_FPS,
            ">=",
            "target",
            note=f"paper {r.paper_fps:g} FPS on a 2010 laptop",
        )
        for r in runs
    ]
    checks += [
        Check(
            f"{r.model} frames per second on {data.mesh} with the compiled backend",
            r.fps,
            COMPILED_TARGET_FPS,
            ">=",
            "target",
            note="the compiled backend's target on a 2-core machine",
        )
        for r in runs
        if r.backend == "numba"
    ]
    for a in data.backend_agreement:
        diff = a.relative_difference
        checks.append(
            Check(
                f"{a.model}: the {a.backend} run's maximum displacement curve against the "
                f"{a.reference} run's (largest difference / peak)",
                diff,
                BACKEND_AGREEMENT_TOL,
                note="" if diff is not None else "not comparable: a run failed or took other steps",
            )
        )
    return checks


def _liver_blocks(
    data: LiverData,
    params: LiverParameters,
    osc: Optional[OscillationData],
    relative_to: Optional[str],
) -> List:
    """The liver section of the report: setting, figures, tables and findings."""
    from common.blocks import Figure, Paragraph

    def rel(path: str) -> str:
        return os.path.relpath(path, relative_to) if relative_to else path

    solver = LIVER_SOLVER if params.solver == LIVER_SOLVER else params.solver
    blocks: List = [
        Paragraph(
            f"Mesh {data.mesh_description}, {data.n_fixed} fixed nodes "
            f"({'; '.join(data.fixed_regions)}), gravity {list(params.gravity)} m/s^2, material "
            f"{type(params.material).__name__}, {data.duration:g} s simulated. FPS are time "
            "steps per wall-clock second of stepping (assembly, solve, substeps included) on this "
            f"machine; the linear solver: {solver.label()}. A step the integrator could not take "
            f"whole was retried in halves (down to dt/{2**params.max_halvings})."
        )
    ]
    blocks += [
        Figure(rel(p), _CAPTIONS.get(os.path.splitext(os.path.basename(p))[0], os.path.basename(p)))
        for p in data.figures
    ]
    blocks += _run_tables(data)
    if osc is not None:
        blocks += _oscillation_blocks(osc)
    if data.series:
        blocks.append(
            Paragraph(
                "ParaView time series (displacement, J, pressure): "
                + ", ".join(rel(p) for p in data.series)
            )
        )
    return blocks


#: The FPS table's columns: (header, value of a run).
_FPS_COLUMNS = (
    ("model", lambda r: r.model),
    ("backend", lambda r: r.backend),
    ("dt (s)", lambda r: r.dt),
    ("steps", lambda r: f"{r.steps}/{r.steps_planned}"),
    ("steps in substeps", lambda r: r.steps_split),
    ("substeps", lambda r: r.substeps_total),
    ("max inverted cells", lambda r: r.inverted_cells_max),
    ("CG / step", lambda r: r.cg_iterations_mean),
    ("final max |u| (mm)", lambda r: 1e3 * r.final_max_displacement),
    ("FPS", lambda r: r.fps),
    ("CPU FPS", lambda r: r.cpu_fps),
    ("paper FPS", lambda r: r.paper_fps),
    ("target", lambda r: _fps_target(r)),
    ("error", lambda r: r.error or ""),
)


def _run_tables(data: LiverData) -> List:
    """The FPS table, the backends' agreement and the step split."""
    from common.blocks import Table

    caption = (
        f"Frames per second and substeps, per backend (targets: {TARGET_FPS:g} FPS, the "
        f"real-time bar; {COMPILED_TARGET_FPS:g} FPS for the compiled backend)"
    )
    rows = [tuple(value(r) for _, value in _FPS_COLUMNS) for r in data.runs]
    tables = [Table(tuple(h for h, _ in _FPS_COLUMNS), rows, caption=caption)]
    if data.backend_agreement:
        tables.append(_agreement_table(data.backend_agreement))
    if data.step_split:
        tables.append(_split_table(data.step_split))
    return tables


def _agreement_table(agreement: Sequence[BackendAgreement]):
    from common.blocks import Table

    header = ("model", "backend", "against", "max displacement curve: largest difference / peak")
    rows = [(a.model, a.backend, a.reference, a.relative_difference) for a in agreement]
    caption = (
        f"The backends give the same trajectory (tolerance {BACKEND_AGREEMENT_TOL:g}: the "
        "linear solve's own tolerance bounds the drift)"
    )
    return Table(header, rows, caption=caption)


def _split_table(split: Sequence[StepSplit]):
    from common.blocks import Table

    rows = [
        (
            s.model,
            s.backend,
            s.ms_per_step,
            *(f"{100 * s.shares[p]:.0f} %" for p in PHASES),
        )
        for s in split
    ]
    caption = (
        f"Where a step's time goes; the paper: hyperelastic about "
        f"{100 * PAPER_HYPERELASTIC_SHARE:.0f} %"
    )
    return Table(("model", "backend", "ms / step", *PHASES), rows, caption=caption)


def _oscillation_blocks(osc: OscillationData) -> List:
    from common.blocks import Paragraph, Table

    rows = [
        (
            r.model,
            r.dt,
            "yes" if r.completed else "no: " + (r.error or "")[:90],
            r.extrema,
            None if r.first_peak is None else 1e3 * r.first_peak,
            1e3 * r.final,
            r.period,
            r.decay_rate,
            r.euler_decay_rate,
            r.steps_split,
        )
        for r in osc.table
    ]
    return [
        Table(
            (
                "model",
                "dt (s)",
                "completed",
                "extrema",
                "first peak (mm)",
                "final (mm)",
                "period (s)",
                "decay rate (1/s)",
                "backward Euler rate (1/s)",
                "steps in substeps",
            ),
            rows,
            caption=f"Oscillation study on {osc.mesh}, no Rayleigh damping, {osc.duration:g} s",
        ),
        Paragraph(oscillation_findings(osc)),
    ]


def _liver_headline(data: LiverData, osc: Optional[OscillationData], models: Sequence[str]) -> str:
    per_backend = []
    for b in data.backends:
        mine = [r for r in data.runs if r.backend == b]
        fps = " / ".join("failed" if r.fps is None or r.error else f"{r.fps:.0f}" for r in mine)
        per_backend.append(f"{fps} ({b})")
    split = sum(r.steps_split for r in data.runs)
    tz_err = data.terzaghi_error
    headline = (
        f"FPS on {data.mesh}: {', '.join(per_backend)} for {', '.join(models)} (targets 25, "
        f"compiled {COMPILED_TARGET_FPS:g}; paper 7.5 / 7 / 6); {split} step(s) taken in substeps; "
        f"Terzaghi {100 * tz_err:.2f} %"
    )
    if osc is not None:
        headline += (
            f"; oscillation amplitude order at dt {osc.amplitude_ordering_dt:g} s: "
            f"{' > '.join(osc.amplitude_ordering)}"
        )
    return headline


def _liver_protocol(data: LiverData, osc: Optional[OscillationData], full: bool) -> str:
    text = (
        f"{len(data.runs)} runs of {data.duration:g} s on {data.mesh} (backends: "
        f"{', '.join(data.backends)}); oscillation study with the {data.backends[0]} backend "
    )
    if osc is None:
        return text + "not run"
    size = (
        "the full version"
        if full
        else "default size; --full-oscillation runs it over 5 s with dt down to 0.003 s, on the "
        "paper-size liver for the built-in organ"
    )
    return (
        text + f"on {osc.mesh} over {osc.duration:g} s at dt "
        f"{', '.join(f'{d:g}' for d in osc.dts)} s ({size})"
    )


def _fps_target(run: LiverRun) -> str:
    """The FPS target(s) of a run, met or missed."""
    if run.fps is None:
        return "not measured"
    targets = [TARGET_FPS] + ([COMPILED_TARGET_FPS] if run.backend == "numba" else [])
    return ", ".join(f"{t:g}: {'met' if run.fps >= t else 'missed'}" for t in targets)


def oscillation_findings(osc: OscillationData) -> str:
    """What the oscillation study found, in words (from the measured table, whatever it is)."""
    rows = osc.table
    parts = []
    for model in dict.fromkeys(r.model for r in rows):
        mine = sorted((r for r in rows if r.model == model), key=lambda r: r.dt)
        done = [r for r in mine if r.completed]
        rates = ", ".join(
            f"{r.decay_rate:.2g}/s at {r.dt:g} s" for r in done if r.decay_rate is not None
        )
        once = [f"{r.dt:g}" for r in done if r.decay_rate is None and r.extrema > 0]
        none = [f"{r.dt:g}" for r in done if r.extrema == 0]
        failed = [f"{r.dt:g}" for r in mine if not r.completed]
        peaks = ", ".join(f"{1e3 * r.peak:.0f} mm at {r.dt:g} s" for r in done)
        text = f"{model}: peak {peaks}"
        if rates:
            text += f"; oscillation decay {rates}"
        if once:
            text += f"; overshoots but too few swings to measure a decay at dt {', '.join(once)} s"
        if none:
            text += f"; no oscillation (overdamped) at dt {', '.join(none)} s"
        if failed:
            text += f"; refused at dt {', '.join(failed)} s even in substeps"
        parts.append(text)
    order = " > ".join(osc.amplitude_ordering)
    return (
        "Findings. "
        + ". ".join(parts)
        + f". Peak amplitude at dt {osc.amplitude_ordering_dt:g} s, largest first: {order} (the "
        "paper: visco > poro > hyper)."
    )
