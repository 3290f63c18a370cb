"""mjed-verify export DIR: write a conformance kit for an engine to compute
(docs/conventions.md).
"""

from __future__ import annotations

import os

NAME = "export"
ORDER = 60
HELP = "write a conformance kit (meshes, models, positions of each case) for your engine to compute"
EXAMPLES = """examples:
  mjed-verify export kit/                          # all materials, single-tet, all states
  mjed-verify export kit/ --material NeoHookean --mesh cube-small --states uniaxial,random
  mjed-verify export kit/ --energy "mu/2*(I1b-3) + K/2*(J-1)**2" --param mu=1e3 --param K=1e4
then: for each case of kit/manifest.json, read cases/<id>/input, write cases/<id>/output;
      mjed-verify check kit/
"""


def configure(parser) -> None:
    parser.add_argument("dir", metavar="DIR", help="a new or empty directory for the kit")
    from conformance.kit.options import add_model_options

    add_model_options(parser)
    parser.add_argument(
        "--no-probes",
        action="store_true",
        help="leave out the perturbed states (no self-consistency test of the stiffness)",
    )
    parser.add_argument(
        "--precision",
        choices=("double", "single"),
        default="double",
        help="the precision your engine computes in, declared in the kit: "
        "'single' (float32) gives tolerances from float32 round-off and "
        "each case's conditioning",
    )


def run(args) -> int:
    from common.options import InputError
    from conformance.kit.cases import PROBES
    from conformance.kit.options import cases_from_args, reproduce
    from conformance.kit.write import write_kit

    if os.path.exists(args.dir) and (not os.path.isdir(args.dir) or os.listdir(args.dir)):
        raise InputError(
            f"{args.dir}: exists and is not an empty directory; export never writes into one"
        )
    cases = cases_from_args(args, probes=0 if args.no_probes else PROBES)
    try:
        manifest = write_kit(
            args.dir, cases, command=reproduce(NAME, args, args.dir), precision=args.precision
        )
    except FileExistsError as exc:  # another export took the folder after the check above
        raise InputError(str(exc)) from None
    n_main = sum(e["role"] == "case" for e in manifest["cases"])
    print(
        f"wrote {args.dir}: {n_main} cases + {len(manifest['cases']) - n_main} probes; compute "
        f"each cases/<id>/output, then: mjed-verify check {args.dir}"
    )
    return 0
