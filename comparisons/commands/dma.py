"""mjed-verify dma: the simulated rheometer frequency sweep of the paper's Fig. 3."""

from __future__ import annotations

import sys

from common import options as opt

NAME = "dma"
ORDER = 30
HELP = (
    "simulated rheometer (Fig. 3): G', G'' of a Prony StVK cylinder against the Maxwell and "
    "backward-Euler moduli"
)
EXAMPLES = """examples:
  mjed-verify dma                                   # 13 frequencies, ~1000-cell cylinder
  mjed-verify dma --quick --json reports/dma.json   # 5 frequencies on a coarse mesh, a few seconds
  mjed-verify dma --samples-per-period 256          # nearer the continuous moduli
"""


def configure(parser) -> None:
    parser.add_argument(
        "--quick", action="store_true", help="a complete but small run (5 frequencies, ~300 cells)"
    )
    parser.add_argument(
        "--cells", type=int, help="target tetrahedra of the cylinder (default 1000, quick 300)"
    )
    parser.add_argument(
        "--frequencies", type=int, help="number of log-spaced frequencies (default 13, quick 5)"
    )
    parser.add_argument(
        "--samples-per-period", type=int, help="time steps per period (default 64, quick 32)"
    )
    parser.add_argument(
        "--amplitude",
        type=float,
        help="rotation amplitude of the upper plate in rad (default 1e-6)",
    )
    opt.add_json_option(parser)
    opt.add_out_option(parser, "reports/dma")
    opt.add_allow_incomplete_option(parser)


def run(args) -> int:
    from common.terminal import finish
    from comparisons.rheometer.study import SPEC_OPTIONS, rheometer_spec, rheometer_study

    overrides = {k: getattr(args, k) for k in SPEC_OPTIONS}
    try:
        rheometer_spec(args.quick, **overrides)  # refuse a bad value before any work
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None
    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731
    return finish(
        rheometer_study(quick=args.quick, out_dir=args.out, progress=progress, **overrides), args
    )
