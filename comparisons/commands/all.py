"""mjed-verify all: every study, one self-contained report under reports/<run>/."""

from __future__ import annotations

import sys

from comparisons import options as opt

NAME = "all"
ORDER = 1
HELP = "run every study and write reports/<run>/index.html (reports/latest points to the newest complete run)"
EXAMPLES = """examples:
  mjed-verify all                      # the full report on the built-in meshes (the README's main job)
  mjed-verify all --quick              # a complete but smaller report in about a minute
  mjed-verify all --out /tmp/reports --material NeoHookean,Ogden
  xdg-open reports/latest/index.html   # opens from disk, figures embedded
"""

QUICK_MESHES = "single-tet,cube-small"


def configure(parser) -> None:
    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "all (quick: single-tet,cube-small)")
    opt.add_states_option(parser)
    opt.add_out_option(parser, "reports")
    parser.add_argument("--quick", action="store_true", help="smaller meshes and fewer repeats: a complete report in about a minute")
    parser.add_argument("--only", metavar="KEYS", help="comma-separated study keys to run (default: all of them)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")


def run(args) -> int:
    # Every selection is checked before any study starts.
    materials = opt.resolve_materials(args.material)
    states = opt.resolve_states(args.states)
    mesh_spec = args.mesh
    if mesh_spec.startswith("all ("):  # the default, spelled for --help
        mesh_spec = QUICK_MESHES if args.quick else "all"
    mesh_list = opt.resolve_meshes(mesh_spec)

    from comparisons.report.runner import run_report
    from comparisons.report.studies import all_studies

    studies = all_studies(args.quick)
    if args.only:
        keys = [k.strip() for k in args.only.split(",") if k.strip()]
        known = [s.key for s in studies]
        unknown = [k for k in keys if k not in known]
        if unknown or not keys:
            raise opt.InputError(f"unknown study key(s) {unknown}; known: {', '.join(known)}")
        studies = [s for s in studies if s.key in keys]
    outcome = run_report(
        args.out, studies,
        {"materials": materials, "meshes": mesh_list, "states": states, "show_progress": not args.no_progress},
        quick=args.quick, command_line=["mjed-verify", *sys.argv[1:]] if sys.argv[0].endswith("mjed-verify") else None,
    )
    where = outcome.run_dir + "/index.html"
    if not outcome.complete:
        print(f"interrupted: partial report in {where}; reports/latest unchanged", file=sys.stderr)
        return 130
    bad = [s for s in outcome.sections[1:] if s.status not in ("ok", "skipped")]
    print(f"report: {where} (also {args.out}/latest/index.html)")
    for s in bad:
        print(f"  {s.title}: {s.status}: {s.message}")
    return 0 if not bad else 1
