"""mjed-verify equivalence: MJED against the UFL oracle, materials x meshes x states."""

from __future__ import annotations

import sys

from common import options as opt

NAME = "equivalence"
ORDER = 10
HELP = "compare MJED with the UFL oracle for materials x meshes x states"
EXAMPLES = """examples:
  mjed-verify equivalence                          # all materials, built-in meshes, all states
  mjed-verify equivalence --material NeoHookean --mesh cube-small
  mjed-verify equivalence --material all --mesh cube-paper --json eq.json
  mjed-verify equivalence --mesh path/to/organ.msh --states rest,random
  mpirun -n 2 mjed-verify equivalence --mesh cube-paper   # oracle distributed over 2 ranks
"""


def configure(parser) -> None:
    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "all")
    opt.add_states_option(parser)
    opt.add_json_option(parser)
    opt.add_allow_incomplete_option(parser)
    parser.add_argument(
        "--quiet", action="store_true", help="print only the checks and the verdict, not every case"
    )


def run(args) -> int:
    materials = opt.resolve_materials(args.material)
    states = opt.resolve_states(args.states)
    mesh_list = opt.resolve_meshes(args.mesh)

    from common.terminal import finish
    from comparisons.equivalence.study import equivalence_study
    from reference_fem import dolfinx_available

    progress = (
        None if args.quiet else (lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True))
    )
    if not dolfinx_available():  # the study says NOT RUN, with the reason
        return finish(equivalence_study(mesh_list, materials, states), args)

    # Under mpirun the oracle is distributed over all ranks; rank 0 runs MJED, compares,
    # prints and writes the JSON, and every rank exits with rank 0's code.
    from reference_fem.compat import comm_world

    comm = comm_world()
    if comm.size == 1:
        return finish(
            equivalence_study(mesh_list, materials, states, progress=progress),
            args,
            details=not args.quiet,
        )
    from reference_fem.distributed import abort_on_error

    with abort_on_error(comm):  # an error on one rank must not leave the others waiting
        result = equivalence_study(mesh_list, materials, states, progress=progress, comm=comm)
        code = finish(result, args, details=not args.quiet) if comm.rank == 0 else 0
        return comm.bcast(code, root=0)
