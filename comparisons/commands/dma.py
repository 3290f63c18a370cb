"""mjed-verify dma: the simulated rheometer frequency sweep of the paper's Fig. 3."""

from __future__ import annotations

import sys

from comparisons import options as opt

NAME = "dma"
ORDER = 30
HELP = "simulated rheometer (Fig. 3): G', G'' of a Prony StVK cylinder against the Maxwell and backward-Euler moduli"
EXAMPLES = """examples:
  mjed-verify dma                                   # 13 frequencies, ~1000-cell cylinder, figure in reports/dma
  mjed-verify dma --quick --json reports/dma.json   # 5 frequencies on a coarse mesh, a few seconds
  mjed-verify dma --samples-per-period 256          # closer to the continuous moduli (BE error ~ omega dt)
"""

#: The sweep must reproduce the exact backward-Euler transfer function to this relative error
#: (what is left is O(amplitude^2) geometric nonlinearity and round-off, about 1e-10).
DISCRETE_TOL = 1e-7


def configure(parser) -> None:
    parser.add_argument("--quick", action="store_true", help="a complete but small run (5 frequencies, ~300 cells)")
    parser.add_argument("--cells", type=int, help="target tetrahedra of the cylinder (default 1000, quick 300)")
    parser.add_argument("--frequencies", type=int, help="number of log-spaced frequencies (default 13, quick 5)")
    parser.add_argument("--samples-per-period", type=int, help="time steps per period (default 64, quick 32)")
    parser.add_argument("--amplitude", type=float, help="rotation amplitude of the upper plate in rad (default 1e-6)")
    opt.add_json_option(parser)
    opt.add_out_option(parser, "reports/dma")


def run(args) -> int:
    from dataclasses import replace

    from comparisons.rheometer import QUICK_SPEC, RheometerSpec

    spec = QUICK_SPEC if args.quick else RheometerSpec()
    changes = {"target_cells": args.cells, "n_frequencies": args.frequencies,
               "samples_per_period": args.samples_per_period, "amplitude": args.amplitude}
    try:
        spec = replace(spec, **{k: v for k, v in changes.items() if v is not None})
    except ValueError as exc:
        raise opt.InputError(str(exc)) from None

    from comparisons.rheometer import format_table, run_rheometer

    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731
    result = run_rheometer(spec=spec, out=args.out, json_path=args.json, progress=progress)
    m = result["mesh"]
    print(f"cylinder {2e3 * spec.radius:g} mm x {1e3 * spec.height:g} mm, {m['n_cells']} cells, {m['n_nodes']} nodes; "
          f"StVK G0 = {spec.G0:g} Pa, alphas {spec.alphas}, taus {spec.taus} s; theta0 = {spec.amplitude:g} rad, "
          f"{spec.samples_per_period} steps per period, quasi-static implicit Euler")
    print(format_table(result))
    e = result["errors"]
    print(f"relative error vs continuous generalised Maxwell: mean {e['continuous']['mean']:.2e}, max {e['continuous']['max']:.2e}"
          f" (backward Euler's own O(omega dt) error)")
    print(f"relative error vs exact backward-Euler response:  mean {e['discrete']['mean']:.2e}, max {e['discrete']['max']:.2e}"
          f" (tolerance {DISCRETE_TOL:g})")
    for path in result["figures"]:
        print(f"figure: {path}")
    print(f"{result['elapsed_s']:.1f} s")
    return 0 if e["discrete"]["max"] <= DISCRETE_TOL else 1
