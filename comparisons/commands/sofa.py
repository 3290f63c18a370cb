"""mjed-verify sofa: SOFA's own force fields through the checker, and timed beside the project's
kernels (needs the SOFA engine program: python -m conformance.adapters.sofa).
"""

from __future__ import annotations

import sys
from pathlib import Path

from common import options as opt

NAME = "sofa"
ORDER = 65
HELP = "SOFA's MJED and classical force fields checked against the oracle, and timed"
EXAMPLES = """examples:
  python -m conformance.adapters.sofa build --sofa ~/sofa/build   # once: the engine program
  mjed-verify sofa --plugin-meshes ~/SofaMJEDFEM/examples/data --json sofa.json
  mjed-verify sofa --quick --material NeoHookean,Ogden
Without the engine program the study is NOT RUN (exit 3) and says how to build it.
"""


def configure(parser) -> None:
    parser.add_argument(
        "--plugin-meshes",
        type=Path,
        metavar="DIR",
        help="SofaMJEDFEM's examples/data: its cylinder*.vtk meshes are checked too",
    )
    parser.add_argument(
        "--material",
        default=None,
        help="comma-separated materials (default: every declared material with a SOFA law)",
    )
    parser.add_argument(
        "--forcefields",
        default="mjed,hyperelasticity,standard",
        help="comma-separated: mjed, hyperelasticity, standard (default: all three)",
    )
    parser.add_argument("--calls", type=int, default=10, help="timed calls per method (median)")
    parser.add_argument("--quick", action="store_true", help="small meshes (a partial run)")
    parser.add_argument("--skip-checks", action="store_true", help="time only (a partial run)")
    parser.add_argument("--skip-timing", action="store_true", help="check only (a partial run)")
    opt.add_json_option(parser)
    opt.add_allow_incomplete_option(parser)


def run(args) -> int:
    from common.options import InputError
    from common.terminal import finish
    from comparisons.sofa.setup import FORCEFIELDS, sofa_materials
    from comparisons.sofa.study import sofa_study

    forcefields = [f for f in args.forcefields.split(",") if f]
    unknown = [f for f in forcefields if f not in FORCEFIELDS]
    if unknown:
        raise InputError(f"--forcefields: unknown {unknown}; known: {', '.join(FORCEFIELDS)}")
    materials = None
    if args.material:
        materials = [m for m in args.material.split(",") if m]
        offered = sofa_materials()
        bad = [m for m in materials if m not in offered]
        if bad:
            raise InputError(f"--material: no SOFA law for {bad}; SOFA has: {', '.join(offered)}")
    if args.plugin_meshes is not None and not args.plugin_meshes.is_dir():
        raise InputError(f"--plugin-meshes {args.plugin_meshes}: not a folder")
    if args.calls < 1:
        raise InputError(f"--calls must be >= 1, got {args.calls}")
    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731
    command = (
        "mjed-verify sofa " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else "mjed-verify sofa"
    )
    result = sofa_study(
        args.plugin_meshes,
        args.quick,
        materials,
        forcefields,
        timing_calls=args.calls,
        checks_on=not args.skip_checks,
        timing_on=not args.skip_timing,
        progress=progress,
        command=command,
    )
    return finish(result, args)
