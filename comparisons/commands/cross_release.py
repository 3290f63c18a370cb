"""mjed-verify cross-release: the same oracle cases on every dolfinx stack and on 2 MPI ranks."""

from __future__ import annotations

from comparisons import options as opt

NAME = "cross-release"
ORDER = 90
HELP = "compare the UFL oracle across dolfinx releases (.venv, .venv-modern) and process counts (1e-12)"
EXAMPLES = """examples:
  mjed-verify cross-release --quick
  mjed-verify cross-release --json reports/cross_release.json
  (set up the second stack first: make bootstrap-modern)
"""


def configure(parser) -> None:
    parser.add_argument("--quick", action="store_true", help="two materials and Costa with cell frames, one state")
    opt.add_json_option(parser)


def run(args) -> int:
    from comparisons.cross_release import cross_release_check, format_check

    result = cross_release_check(quick=args.quick)
    print(format_check(result))
    if args.json:
        opt.write_json(args.json, result)
    verdict = "passed" if result["passed"] else "FAILED"
    if len(result["stacks"]) < 2:
        verdict += " (fewer than two stacks ran: nothing was compared)"
    print(f"cross-release check: {verdict}")
    return 0 if result["passed"] else 1
