"""mjed-verify timing: force and stiffness assembly time (paper Fig. 2), NumPy and compiled
MJED and classical FEM, dolfinx and peer libraries; or --scaling. Parses options, runs the
study (comparisons.timing.study), prints its result.
"""

from __future__ import annotations

import sys

from common import options as opt

NAME = "timing"
ORDER = 40
HELP = (
    "time force+stiffness (paper Fig. 2): MJED and classical FEM, NumPy and compiled, dolfinx, "
    "FElupe"
)
EXAMPLES = """examples:
  mjed-verify timing                                  # all materials on cube-paper
  mjed-verify timing --protocol paper                 # the paper's 100 calls x 3 repeats
  mjed-verify timing --material NeoHookean --methods mjed,mjed-numba,classical-numba
  mjed-verify timing --scaling                        # 1e3 to 1e6 cells, time and memory per cell
  mjed-verify timing --quick --json reports/timing/t.json

exit codes: 0 every check passed and every target was met on a complete run; 1 a result check
failed; 2 bad input; 3 a speed target missed or part of the study not run (e.g. Numba or
dolfinx not installed, --quick).
"""


def configure(parser) -> None:
    from comparisons.timing.protocol import PROTOCOLS
    from comparisons.timing.study import DEFAULT_METHODS, SCALING_METHODS

    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "cube-paper", several=False)
    parser.add_argument(
        "--methods",
        default=None,
        help=f"comma-separated methods (default: {','.join(DEFAULT_METHODS)}; with --scaling: "
        f"{','.join(SCALING_METHODS)}); 'mjed' is required (the reference)",
    )
    parser.add_argument(
        "--protocol",
        default="budget",
        choices=[p for p in PROTOCOLS if p != "quick"],
        help="budget (default): repeat until the spread is <= 5 %% or the budget is spent; paper: "
        "100 calls x 3 repeats per measurement",
    )
    parser.add_argument(
        "--no-memory", action="store_true", help="skip the peak-memory subprocesses"
    )
    parser.add_argument(
        "--scaling",
        action="store_true",
        help="instead: force+stiffness from about 1e3 to 1e6 cells on structured cubes",
    )
    parser.add_argument(
        "--max-cells", type=int, default=None, help="--scaling: largest mesh (default: about 1e6)"
    )
    parser.add_argument(
        "--scaling-material",
        default="NeoHookean",
        help="--scaling: the material (default: NeoHookean)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="a complete but small run (cube-small, seconds)"
    )
    opt.add_json_option(parser)
    opt.add_out_option(parser, "reports/timing")


def _methods(spec, default):
    from comparisons.timing.study import check_methods

    try:
        return check_methods(spec if spec is not None else default)
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None


def run(args) -> int:
    from common.result import exit_code

    if args.max_cells is not None and args.max_cells < 6:
        raise opt.InputError(f"--max-cells must be >= 6, got {args.max_cells}")
    if args.json:
        opt.check_writable_destination(args.json, is_dir=False)
    if args.out:
        opt.check_writable_destination(args.out, is_dir=True)
    result = _run_scaling(args) if args.scaling else _run_timing(args)
    print(render_text(result))
    if args.json:
        opt.write_json(args.json, result.to_dict())
        print(f"written: {args.json}")
    return exit_code([result])


def _progress(msg: str) -> None:
    print(f"  ... {msg}", file=sys.stderr, flush=True)


def _run_scaling(args):
    from common.cases import default_material
    from comparisons.timing.study import SCALING_METHODS, scaling_command, scaling_study

    try:
        default_material(args.scaling_material)
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None
    methods = _methods(args.methods, SCALING_METHODS)
    options = dict(
        quick=args.quick,
        material=args.scaling_material,
        methods=methods,
        max_cells=args.max_cells,
        out_dir=args.out,
    )
    command = scaling_command(json_path=args.json, **options)
    return scaling_study(progress=_progress, command=command, **options)


def _run_timing(args):
    from common.cases import DEFAULT_MATERIALS
    from comparisons.timing.study import DEFAULT_METHODS, timing_command, timing_study

    materials = opt.resolve_materials(args.material)
    ((label, _, _),) = opt.resolve_meshes(args.mesh, several=False)
    names = [k for k, v in DEFAULT_MATERIALS.items() if any(v is m for m in materials)]
    options = dict(
        quick=args.quick,
        protocol=args.protocol,
        methods=_methods(args.methods, DEFAULT_METHODS),
        memory=not args.no_memory,
        out_dir=args.out,
    )
    command = timing_command(names, label, json_path=args.json, **options)
    return timing_study(names, label, progress=_progress, command=command, **options)


def render_text(result) -> str:
    """The result as plain text: status, headline, the blocks' tables, the checks."""
    from common.blocks import Figure, Paragraph, Preformatted, Table

    lines = [
        f"{result.title}",
        f"status: {result.status.value}" + (" (partial)" if result.partial else ""),
        result.headline,
    ]
    if result.reason:
        lines.append(f"reason: {result.reason}")
    for item in result.not_covered:
        lines.append(f"not covered: {item}")
    lines.append(f"protocol: {result.protocol}")
    for b in result.blocks:
        lines.append("")
        if isinstance(b, Table):
            if b.caption:
                lines.append(b.caption)
            lines.append(" | ".join(str(h) for h in b.headers))
            lines += [" | ".join(str(c) for c in row) for row in b.rows]
        elif isinstance(b, Figure):
            lines.append(f"figure: {b.path} ({b.caption})")
        elif isinstance(b, (Paragraph, Preformatted)):
            lines.append(b.text)
    lines += ["", f"reproduce: {result.command}"]
    return "\n".join(lines)
