"""mjed-verify liver: the liver under gravity, three models (paper Fig. 1, Fig. 2 left and Fig. 4).

This module only parses options, calls comparisons.liver.study.liver_study and prints its result.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from typing import Dict, List, Optional

from common import options as opt
from common.cases import material_names

NAME = "liver"
ORDER = 40
HELP = (
    "liver under gravity: hyperelastic, visco- and visco-poro-hyperelastic runs on your organ "
    "mesh, substeps, FPS, where a step's time goes, the oscillation study (Fig. 4), ParaView series"
)
EXAMPLES = """examples:
  mjed-verify liver                                   # the paper-size liver, 30 steps of 0.3 s
  mjed-verify liver --quick                           # coarse liver, 6 steps: seconds
  mjed-verify liver --mesh organ.msh --units cm --gravity 0,-9.81,0 --fixed nodes:ids.txt
  mjed-verify liver --mesh organ.vtu --fixed sphere:0,0.05,0.02,0.02 --material NeoHookean \\
                    --param mu=2000 --param lam=20000
  mjed-verify liver --material ArrudaBoyce --sofa-parameters "2000 20000" --dt 0.1 \\
                    --rayleigh-mass 0.05
  mjed-verify liver --mesh organ.msh --fix-orientation  # reorder inverted cells (counted)
  mjed-verify liver --backends cuda,numba --no-series  # the GPU (FP64) beside the compiled kernel

meshes (--mesh): built-in liver, liver-coarse, or a volume mesh file: gmsh .msh (legacy 1.0
$NOD/$ELM, 2.2, 4.1), .vtk, .vtu, Medit .mesh, Abaqus .inp. Surface files (.stl, .obj) are
refused with the gmsh commands that mesh their inside. Node numbers are kept as in the file.

region specs (--fixed, repeatable, union), in the mesh file's units:
  box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX | sphere:CX,CY,CZ,R
  nodes:FILE   node ids as the mesh file numbers them (gmsh node numbers and Abaqus labels as
               written, Medit 1-based, VTK 0-based; 0-based for the built-in meshes)
  index:FILE   0-based positions in the order the nodes are read, whatever the format
Default: vena cava and suspensory ligament, placed relative to the bounding box of a z-up mesh.

materials (--material): {materials};
parameters by --param NAME=VALUE (the dataclass fields, e.g. mu, k0, N) or a SOFA ParameterSet
(--sofa-parameters, SOFA's order). Default: ArrudaBoyce mu=2000 k0=20000 N=8. --allow-inverted
lets inverted cells continue (counted and reported) for a material whose energy is finite at
J <= 0 (of the built-in materials, St Venant-Kirchhoff only), as the paper's section 2.3 allows.

exit codes: 0 every check passed and the run is complete; 1 a run failed or Terzaghi is off;
2 bad input; 3 an FPS target missed or a partial run (--quick, --models, --no-oscillation).
""".replace("{materials}", ", ".join(material_names()))


def configure(parser) -> None:
    _mesh_options(parser)
    _time_options(parser)
    _material_options(parser)
    _run_options(parser)


def _mesh_options(parser) -> None:
    """The organ: mesh, units, supports and gravity."""
    group = parser.add_argument_group("the organ: mesh, units, supports and gravity")
    opt.add_mesh_option(parser, "liver", several=False)
    group.add_argument(
        "--units", choices=("m", "cm", "mm"), help="length unit of the mesh file (default m)"
    )
    group.add_argument("--scale", type=float, help="metres per mesh unit (instead of --units)")
    group.add_argument(
        "--fix-orientation",
        action="store_true",
        help="swap two nodes of every negatively oriented cell (the number reordered is reported)",
    )
    group.add_argument(
        "--fixed",
        action="append",
        metavar="REGION",
        help="fixed nodes: box:..., sphere:..., nodes:FILE or index:FILE (repeatable; default vena "
        "cava + ligament)",
    )
    group.add_argument(
        "--allow-disconnected",
        action="store_true",
        help="accept a mesh in several parts when each part has a fixed node (warned); a part "
        "with no fixed node is always refused",
    )
    group.add_argument("--gravity", metavar="X,Y,Z", help="gravity in m/s^2 (default 0,0,-9.81)")


def _time_options(parser) -> None:
    """Time stepping and the linear solver."""
    group = parser.add_argument_group("time stepping and the linear solver")
    group.add_argument(
        "--steps",
        type=int,
        default=None,
        help="steps of the dt runs (default 30, quick 6); the porous run covers the same time at "
        "its own step",
    )
    group.add_argument("--dt", type=float, help="time step in s (default 0.3)")
    group.add_argument(
        "--dt-porous", type=float, help="time step of the porous run in s (default dt / 2)"
    )
    group.add_argument(
        "--max-halvings",
        type=int,
        help="a failed step is retried in halves down to dt/2^N (default 4)",
    )
    group.add_argument(
        "--max-volume-change",
        type=float,
        help="a step changing a cell's volume by more than this factor is retried in substeps "
        "(default 1.5)",
    )
    group.add_argument(
        "--solver",
        default="factorized",
        choices=("factorized", "jacobi", "block-jacobi", "direct"),
        help="linear solver: CG preconditioned by a kept sparse LU (default), by Jacobi or by 3x3 "
        "node blocks, or a direct sparse LU every step (comparison point)",
    )


def _material_options(parser) -> None:
    """Material, density, damping and permeability."""
    group = parser.add_argument_group("material, density, damping and permeability")
    group.add_argument("--material", help="hyperelastic material (default ArrudaBoyce)")
    group.add_argument(
        "--param", action="append", metavar="NAME=VALUE", help="a material parameter (repeatable)"
    )
    group.add_argument(
        "--sofa-parameters", metavar="'V1 V2 ...'", help="the material from a SOFA ParameterSet"
    )
    group.add_argument(
        "--ogden-order", choices=("sofa", "mjed"), default="sofa", help="Ogden ParameterSet order"
    )
    group.add_argument("--density", type=float, help="kg/m^3 (default 1000)")
    group.add_argument(
        "--rayleigh-mass", type=float, help="Rayleigh mass coefficient r_M in 1/s (default 0.1)"
    )
    group.add_argument(
        "--rayleigh-stiffness",
        type=float,
        help="Rayleigh stiffness coefficient r_K in s (default 0.1)",
    )
    group.add_argument(
        "--kappa",
        type=float,
        default=None,
        help="permeability in m^4/(N s) (default 5e-6; the paper prints 20)",
    )
    group.add_argument(
        "--allow-inverted",
        action="store_true",
        help="accept inverted cells (counted) for a material finite at J <= 0 (regularisation on)",
    )


def _run_options(parser) -> None:
    """What runs, and where the results go."""
    group = parser.add_argument_group("what runs, and where the results go")
    group.add_argument(
        "--models",
        default="all",
        help="'all' or a comma-separated list of: hyperelastic, visco-hyperelastic, "
        "visco-poro-hyperelastic",
    )
    group.add_argument(
        "--backends",
        default="numpy,numba",
        help="comma-separated MJED backends, each running every model: numpy (the NumPy engine), "
        "numba (the compiled kernel; left out, and said so, without Numba), cuda and cuda-fp32 "
        "(the kernel on an NVIDIA GPU in FP64 or FP32, each step solved by CG on the device; "
        "left out, 'not run: no GPU', without one). Default: numpy,numba; the first is the "
        "reference the others are checked against and the one the figures show",
    )
    group.add_argument(
        "--quick", action="store_true", help="coarse liver mesh, 6 steps, a short oscillation study"
    )
    group.add_argument("--no-oscillation", action="store_true", help="skip the oscillation study")
    group.add_argument(
        "--full-oscillation",
        action="store_true",
        help="the oscillation study on the paper-size liver over 5 s with dt down to 0.003 s "
        "(minutes)",
    )
    group.add_argument(
        "--no-series",
        action="store_true",
        help="do not write the ParaView time series (.pvd + .vtu)",
    )
    opt.add_json_option(parser)
    opt.add_out_option(parser, os.path.join("reports", "liver"))


def _gravity(text: str):
    try:
        g = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise opt.InputError(
            f"--gravity {text!r}: expected X,Y,Z in m/s^2, e.g. 0,-9.81,0"
        ) from None
    if len(g) != 3:
        raise opt.InputError(
            f"--gravity {text!r}: expected three comma-separated numbers, got {len(g)}"
        )
    return g


def _param_values(items: Optional[List[str]]) -> Dict[str, object]:
    out: Dict[str, object] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise opt.InputError(f"--param {item!r}: expected NAME=VALUE, e.g. mu=2000")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            out[name.strip()] = value.strip()  # e.g. Ogden's tangent="exact"
    return out


def material_from_options(
    name: Optional[str], params: Optional[List[str]], sofa: Optional[str], ogden_order: str
):
    """The material the options describe, or None for the liver's default."""
    from common.cases import default_material
    from comparisons.liver.study import LiverParameters
    from mjed.materials import from_sofa

    if name is None:
        if params or sofa:
            raise opt.InputError("--param and --sofa-parameters need --material NAME")
        return None
    if sofa is not None:
        if params:
            raise opt.InputError("give --param or --sofa-parameters, not both")
        try:
            return from_sofa(name, sofa, ogden_order=ogden_order)
        except ValueError as exc:
            raise opt.InputError(f"--sofa-parameters: {exc}") from None
    try:
        base = default_material(name)
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None
    liver_default = LiverParameters().material
    if isinstance(liver_default, type(base)):
        base = liver_default  # the liver's own parameters, not the equivalence study's
    values = _param_values(params)
    known = {f.name for f in dataclasses.fields(base)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise opt.InputError(
            f"--param {unknown[0]}: not a parameter of {type(base).__name__} "
            f"({', '.join(sorted(known))})"
        )
    try:
        return dataclasses.replace(base, **values)
    except (TypeError, ValueError) as exc:
        raise opt.InputError(f"--material {name}: {exc}") from None


def _models_and_backends(args):
    """The --models and --backends lists (InputError naming a backend that does not exist)."""
    from comparisons.liver.setup import KNOWN_BACKENDS
    from comparisons.liver.study import MODELS

    models = (
        list(MODELS)
        if args.models.strip().lower() == "all"
        else [m.strip() for m in args.models.split(",") if m.strip()]
    )
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    unknown = [b for b in backends if b not in KNOWN_BACKENDS]
    if unknown or not backends:
        raise opt.InputError(
            f"--backends {args.backends!r}: expected a comma-separated list of "
            f"{', '.join(KNOWN_BACKENDS)}"
        )
    return models, backends


#: LiverParameters fields given on the command line as they are (None: the default).
_PARAMETER_NAMES = (
    "dt",
    "dt_porous",
    "density",
    "rayleigh_mass",
    "rayleigh_stiffness",
    "kappa",
    "max_halvings",
    "max_volume_change",
)


def _liver_parameters(args):
    """The LiverParameters of the command line (InputError when a value is refused)."""
    from comparisons.liver.study import LIVER_SOLVER, LiverParameters

    changes: Dict[str, object] = {}
    if args.solver != "factorized":
        changes["solver"] = (
            dataclasses.replace(LIVER_SOLVER, solver="direct")
            if args.solver == "direct"
            else dataclasses.replace(LIVER_SOLVER, preconditioner=args.solver)
        )
    material = material_from_options(
        args.material, args.param, args.sofa_parameters, args.ogden_order
    )
    if material is not None:
        changes["material"] = material
    if args.gravity is not None:
        changes["gravity"] = _gravity(args.gravity)
    changes.update({n: getattr(args, n) for n in _PARAMETER_NAMES if getattr(args, n) is not None})
    if args.allow_inverted:
        changes["allow_inverted"] = True
    try:
        return LiverParameters(**changes)
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None


def liver_options(args) -> dict:
    """The liver_study keyword arguments of the parsed command line (InputError on bad input)."""
    from comparisons.liver.organ import scale_of

    models, backends = _models_and_backends(args)
    if args.steps is not None and args.steps < 1:
        raise opt.InputError(f"--steps must be a positive integer, got {args.steps}")
    scale_of(args.units, args.scale)  # refuses both, or a bad scale, before any work
    params = _liver_parameters(args)
    return dict(
        quick=args.quick,
        out_dir=args.out,
        series=not args.no_series,
        mesh=args.mesh,
        fixed=args.fixed,
        steps=args.steps,
        units=args.units,
        scale=args.scale,
        fix_orientation=args.fix_orientation,
        params=params,
        models=models,
        oscillation=not args.no_oscillation,
        full_oscillation=args.full_oscillation,
        backends=backends,
        allow_disconnected=args.allow_disconnected,
    )


def run(args) -> int:
    from common.result import exit_code
    from comparisons.liver.records import LiverData
    from comparisons.liver.study import liver_study
    from meshes.io import one_line_warnings

    kwargs = liver_options(args)

    def progress(msg: str) -> None:
        print(f"  ... {msg}", file=sys.stderr, flush=True)

    with one_line_warnings():
        result = liver_study(progress=progress, **kwargs)
    data = LiverData.from_dict(result.data)
    print(
        f"liver under gravity on {data.mesh_description}, {data.n_fixed} fixed, "
        f"{data.duration:g} s simulated"
    )
    _print_runs(data.runs)
    _print_findings(data)
    for path in data.figures + data.series:
        print(f"  wrote {path}")
    left_out = list(result.not_covered) + [f"not measured: {c.name}" for c in result.unmeasured]
    partial = f" (partial: {'; '.join(left_out)})" if result.partial else ""
    print(f"status: {result.status.value}{partial}: {result.reason or result.headline}")
    print(f"reproduce: {result.command}")
    if args.json:
        opt.write_json(args.json, result.to_dict())
    return exit_code([result])


def _print_runs(runs) -> None:
    """One line per run: steps, substeps, displacement, CG, frame rates."""
    print(
        f"  {'model':26s} {'backend':9s} {'dt (s)':>6s} {'steps':>7s} {'split':>5s} "
        f"{'substeps':>8s} {'inverted':>8s} {'final max |u| (mm)':>18s} {'CG/step':>7s} "
        f"{'FPS':>6s} {'CPU FPS':>7s} {'paper':>5s}"
    )
    for r in runs:
        steps = f"{r.steps}/{r.steps_planned}"
        cg = r.cg_iterations_mean
        cg = f"{cg:7.1f}" if cg is not None else f"{'-':>7s}"
        fps = f"{r.fps:6.1f} {r.cpu_fps:7.1f}" if r.fps else f"{'-':>6s} {'-':>7s}"
        print(
            f"  {r.model:26s} {r.backend:9s} {r.dt:6.3g} {steps:>7s} "
            f"{r.steps_split:5d} {r.substeps_total:8d} {r.inverted_cells_max:8d} "
            f"{1e3 * r.final_max_displacement:18.2f} {cg} {fps} {r.paper_fps:5.1f}"
        )
        if r.error:
            print(f"    FAILED: {r.error}")
    if runs:
        fields = "; ".join(dict.fromkeys(f"{r.backend}: {r.force_field}" for r in runs))
        solvers = "; ".join(dict.fromkeys(r.solver for r in runs))
        print(f"  linear solver: {solvers}; force fields: {fields}")


def _print_findings(data) -> None:
    """Backend agreement, the step split, the oscillation findings and Terzaghi."""
    from comparisons.liver.study import PAPER_HYPERELASTIC_SHARE, oscillation_findings

    for a in data.backend_agreement:
        d = a.relative_difference
        diff = "not comparable" if d is None else f"{d:.1e}"
        print(
            f"  {a.model}: {a.backend} trajectory against {a.reference}: largest "
            f"difference / peak {diff}"
        )
    for s in data.step_split:
        shares = ", ".join(f"{p} {100 * v:.0f} %" for p, v in s.shares.items())
        print(f"  step split, {s.model}, {s.backend} ({s.ms_per_step:.1f} ms/step): {shares}")
    if data.step_split:
        share = 100 * PAPER_HYPERELASTIC_SHARE
        print(f"  (the paper: hyperelastic force + stiffness about {share:.0f} % of a step)")
    if data.oscillation is not None:
        print("  " + oscillation_findings(data.oscillation))
    tz = ", ".join(f"T_v {t.T_v:g}: {100 * t.relative_l2_error:.2f} %" for t in data.terzaghi.times)
    print(f"  Terzaghi check of the pressure step (relative L2 error of P, tolerance 1 %): {tz}")
