"""mjed-verify all: every study, one self-contained report under reports/<run>/."""

from __future__ import annotations

import sys

from common import options as opt

NAME = "all"
ORDER = 1
HELP = (
    "run every study and write reports/<run>/index.html (reports/latest points to the newest "
    "complete run)"
)
EXAMPLES = """examples:
  mjed-verify all                      # the full report on the built-in meshes (the main job)
  mjed-verify all --quick              # a small report in about half a minute (exits with 3)
  mjed-verify all --out /tmp/reports --material NeoHookean,Ogden
  mjed-verify all --only equivalence,rheometer   # the other studies are listed as NOT RUN
  xdg-open reports/latest/index.html   # opens from disk, figures embedded
"""

QUICK_MESHES = "single-tet,cube-small"


def configure(parser) -> None:
    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "all (quick: single-tet,cube-small)")
    opt.add_states_option(parser)
    opt.add_out_option(parser, "reports")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smaller meshes and fewer repeats: every section filled, but a partial run (exit code "
        "3)",
    )
    parser.add_argument(
        "--only",
        metavar="KEYS",
        help="comma-separated study keys to run; the others are reported as NOT RUN (exit code 3)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    opt.add_allow_incomplete_option(parser)


def parse_only(spec, known) -> "list | None":
    """--only KEYS -> the keys, checked against the registry (None: every study)."""
    if spec is None:
        return None
    keys = [k.strip() for k in spec.split(",") if k.strip()]
    unknown = [k for k in keys if k not in known]
    if unknown or not keys:
        raise opt.InputError(f"unknown study key(s) {unknown}; known: {', '.join(known)}")
    return keys


def run(args) -> int:
    # Every selection is checked before any study starts.
    materials = opt.resolve_materials(args.material)
    states = opt.resolve_states(args.states)
    mesh_spec = args.mesh
    if mesh_spec.startswith("all ("):  # the default, spelled for --help
        mesh_spec = QUICK_MESHES if args.quick else "all"
    mesh_list = opt.resolve_meshes(mesh_spec)

    from common.verdict import not_covered_lines, status_label, verdict_sentence
    from comparisons.report.runner import run_report
    from comparisons.report.studies import report_studies, study_keys

    only = parse_only(args.only, study_keys())
    outcome = run_report(
        args.out,
        report_studies(),
        {
            "materials": materials,
            "meshes": mesh_list,
            "states": states,
            "show_progress": not args.no_progress,
        },
        quick=args.quick,
        only=only,
        command_line=["mjed-verify", *sys.argv[1:]]
        if sys.argv[0].endswith("mjed-verify")
        else None,
    )
    where = outcome.run_dir + "/index.html"
    if not outcome.complete:
        print(
            f"interrupted: partial report in {where}; {args.out}/latest unchanged", file=sys.stderr
        )
        return outcome.exit_code()
    for r in outcome.results:
        print(f"  {r.title}: {status_label(r)}" + (f": {r.reason}" if r.reason else ""))
    for line in not_covered_lines(outcome.results):
        print(f"  not covered: {line}")
    print(verdict_sentence(outcome.results))
    print(f"report: {where} (also {args.out}/latest/index.html)")
    return outcome.exit_code(allow_incomplete=args.allow_incomplete)
