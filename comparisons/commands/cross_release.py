"""mjed-verify cross-release: the same oracle cases on every dolfinx stack and on 2 MPI ranks."""

from __future__ import annotations

import sys

from common import options as opt

NAME = "cross-release"
ORDER = 90
HELP = (
    "compare the UFL oracle across dolfinx releases (.venv, .venv-modern) and process counts "
    "(1e-12)"
)
EXAMPLES = """examples:
  mjed-verify cross-release --quick
  mjed-verify cross-release --json reports/cross_release.json
  (set up the second stack first: make bootstrap-modern; without it the run is partial and
  exits with 3)
"""


def configure(parser) -> None:
    parser.add_argument(
        "--quick", action="store_true", help="two materials and Costa with cell frames, one state"
    )
    opt.add_json_option(parser)
    opt.add_allow_incomplete_option(parser)


def run(args) -> int:
    from common.terminal import finish
    from comparisons.cross_release.study import cross_release_study

    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731
    return finish(cross_release_study(quick=args.quick, progress=progress), args)
