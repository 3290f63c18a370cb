"""mjed-verify liver: the liver under gravity, three models (paper Fig. 1 and Fig. 4)."""

from __future__ import annotations

import os
import sys

from comparisons import options as opt

NAME = "liver"
ORDER = 40
HELP = "liver under gravity: hyperelastic, visco- and visco-poro-hyperelastic runs, Fig. 1/4, FPS, ParaView series"
EXAMPLES = """examples:
  mjed-verify liver                                   # the paper-size liver, 30 steps of 0.3 s
  mjed-verify liver --quick                           # coarse liver, 6 steps: seconds
  mjed-verify liver --mesh organ.msh --fixed sphere:0,0.05,0.02,0.02 --fixed nodes:ligament.txt
  mjed-verify liver --fixed box:-0.02,0.03,0.0,0.04,0.08,0.08 --steps 50 --json liver.json

region specs (--fixed, repeatable, union): box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX | sphere:CX,CY,CZ,R |
nodes:FILE (0-based indices). Default: vena cava and suspensory ligament, placed relative to
the mesh's bounding box (x left to right, y anterior to posterior, z up; gravity is -z).
"""


def configure(parser) -> None:
    opt.add_mesh_option(parser, "liver", several=False)
    parser.add_argument("--fixed", action="append", metavar="REGION",
                        help="fixed nodes: box:..., sphere:... or nodes:FILE (repeatable; default vena cava + ligament)")
    parser.add_argument("--steps", type=int, default=None,
                        help="steps of the 0.3 s runs (default 30, quick 6); the porous run covers the same time at 0.15 s")
    parser.add_argument("--kappa", type=float, default=None, help="permeability in m^4/(N s) (default 5e-6; the paper prints 20)")
    parser.add_argument("--models", default="all",
                        help="'all' or a comma-separated list of: hyperelastic, visco-hyperelastic, visco-poro-hyperelastic")
    parser.add_argument("--solver", default="factorized", choices=("factorized", "jacobi", "block-jacobi", "direct"),
                        help="linear solver: CG preconditioned by a kept sparse LU (default), by Jacobi or by 3x3 "
                             "node blocks, or a direct sparse LU every step (comparison point)")
    parser.add_argument("--quick", action="store_true", help="coarse liver mesh and 6 steps")
    parser.add_argument("--no-series", action="store_true", help="do not write the ParaView time series (.pvd + .vtu)")
    opt.add_json_option(parser)
    opt.add_out_option(parser, os.path.join("reports", "liver"))


def run(args) -> int:
    from comparisons.liver import MODELS, LiverParameters, run_liver

    models = list(MODELS) if args.models.strip().lower() == "all" else [m.strip() for m in args.models.split(",") if m.strip()]
    solver = dict(linear_solver="direct") if args.solver == "direct" else dict(preconditioner=args.solver)
    params = LiverParameters(**solver)
    if args.kappa is not None:
        try:
            params = LiverParameters(kappa=args.kappa, **solver)
        except ValueError as exc:
            raise opt.InputError(str(exc)) from None
    if args.steps is not None and args.steps < 1:
        raise opt.InputError(f"--steps must be a positive integer, got {args.steps}")

    def progress(msg: str) -> None:
        print(f"  ... {msg}", file=sys.stderr, flush=True)

    result = run_liver(args.mesh, fixed=args.fixed, steps=args.steps, out=args.out, json_path=args.json,
                       quick=args.quick, params=params, models=models, series=not args.no_series, progress=progress)
    print(f"liver under gravity on {result['mesh']} ({result['n_nodes']} nodes, {result['n_cells']} cells, "
          f"{result['n_fixed']} fixed), {result['duration']:g} s simulated")
    print(f"  {'model':26s} {'dt (s)':>6s} {'steps':>5s} {'final max |u| (mm)':>18s} {'CG/step':>8s} {'FPS':>6s} {'CPU FPS':>7s} {'paper':>6s}")
    for r in result["runs"]:
        if r["error"]:
            print(f"  {r['model']:26s} {r['dt']:6.2f} FAILED after {r['steps']} steps: {r['error']}")
            continue
        print(f"  {r['model']:26s} {r['dt']:6.2f} {r['steps']:5d} {1e3 * r['final_max_displacement']:18.2f} "
              f"{r['cg_iterations_mean']:8.1f} {r['fps']:6.1f} {r['cpu_fps']:7.1f} {r['paper_fps']:6.1f}")
    if result["runs"]:
        print(f"  linear solver: {result['runs'][0]['solver']}")
    print(f"  target {25:g} FPS: " + ", ".join(f"{t['model']} {'met' if t['meets_target'] else 'missed'}" for t in result["fps_table"]))
    tz = result["terzaghi"]
    print("  Terzaghi check of the pressure step (relative L2 error of P, tolerance 1 %): "
          + ", ".join(f"T_v {t['T_v']:g}: {100 * t['relative_l2_error']:.2f} %" for t in tz["times"]))
    for path in result["figures"] + result["series"]:
        print(f"  wrote {path}")
    return 0 if result["passed"] else 1
