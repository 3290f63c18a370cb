"""mjed-verify timing: force and stiffness assembly time, MJED vs classical FEM vs dolfinx."""

from __future__ import annotations

import sys

from comparisons import options as opt

NAME = "timing"
ORDER = 40
HELP = "time force+stiffness assembly (paper Fig. 2): mjed, classical FEM and dolfinx, per material"
EXAMPLES = """examples:
  mjed-verify timing                                       # all materials on cube-paper, 100 iterations
  mjed-verify timing --material StVenantKirchhoff --iterations 20 --repeats 5
  mjed-verify timing --methods mjed,classical --json reports/timing/t.json
  mjed-verify timing --scaling                             # 1e3 to 1e6 cells, time and memory per cell
  mjed-verify timing --quick                               # a small complete run (seconds)
"""


def configure(parser) -> None:
    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "cube-paper", several=False)
    parser.add_argument("--iterations", type=int, default=100, help="calls averaged per measurement (default: 100)")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats per measurement (default: 3)")
    parser.add_argument("--methods", default="mjed,classical,dolfinx",
                        help="comma-separated subset of mjed, classical, dolfinx (default: all three)")
    parser.add_argument("--no-memory", action="store_true", help="skip the peak-memory subprocesses")
    parser.add_argument("--scaling", action="store_true",
                        help="instead: force+stiffness from about 1e3 to 1e6 cells on structured cubes")
    parser.add_argument("--max-cells", type=int, default=None, help="--scaling: largest mesh (default: about 1e6)")
    parser.add_argument("--scaling-material", default="NeoHookean", help="--scaling: the material (default: NeoHookean)")
    parser.add_argument("--quick", action="store_true", help="a complete but small run")
    opt.add_json_option(parser)
    opt.add_out_option(parser, "reports/timing")


def _methods(spec: str):
    from comparisons.timing import METHODS

    names = [m.strip() for m in spec.split(",") if m.strip()]
    unknown = [m for m in names if m not in METHODS]
    if unknown or not names:
        raise opt.InputError(f"unknown method(s) {unknown}; known methods: {', '.join(METHODS)}")
    return names


def run(args) -> int:
    methods = _methods(args.methods)
    if args.iterations < 1 or args.repeats < 1:
        raise opt.InputError(f"--iterations and --repeats must be >= 1, got {args.iterations} and {args.repeats}")
    if args.max_cells is not None and args.max_cells < 6:
        raise opt.InputError(f"--max-cells must be >= 6, got {args.max_cells}")

    from reference_fem import dolfinx_available

    if "dolfinx" in methods and not dolfinx_available():
        print("mjed-verify: dolfinx is not installed; timing mjed and classical only", file=sys.stderr)
        methods = [m for m in methods if m != "dolfinx"]
    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731

    if args.scaling:
        from comparisons.cases import default_material
        from comparisons.timing import format_scaling_markdown, run_scaling

        try:
            default_material(args.scaling_material)
        except ValueError as exc:
            raise opt.InputError(str(exc)) from None
        result = run_scaling(material=args.scaling_material, methods=methods, max_cells=args.max_cells,
                             out_dir=args.out, json_path=args.json, quick=args.quick, progress=progress)
        print(format_scaling_markdown(result))
        print("written: " + ", ".join(result["tables"] + result["figures"]))
        return 0

    materials = opt.resolve_materials(args.material)
    (label, _, _), = opt.resolve_meshes(args.mesh, several=False)
    from comparisons.cases import DEFAULT_MATERIALS
    from comparisons.timing import format_markdown, run_timing

    names = [k for k, v in DEFAULT_MATERIALS.items() if any(v is m for m in materials)]
    result = run_timing(names, label, iterations=args.iterations, repeats=args.repeats, methods=methods,
                        out_dir=args.out, json_path=args.json, memory=not args.no_memory, quick=args.quick,
                        progress=progress)
    print(format_markdown(result))
    print("written: " + ", ".join(result["tables"] + result["figures"] + ([args.json] if args.json else [])))
    return 0
