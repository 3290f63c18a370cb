"""mjed-verify equivalence: MJED against the UFL oracle, materials x meshes x states."""

from __future__ import annotations

import sys
import time

from comparisons import options as opt

NAME = "equivalence"
ORDER = 10
HELP = "compare MJED with the UFL oracle for materials x meshes x states"
EXAMPLES = """examples:
  mjed-verify equivalence                                  # all materials, built-in meshes, all states
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
    parser.add_argument("--quiet", action="store_true", help="print only the summary line")


def run(args) -> int:
    materials = opt.resolve_materials(args.material)
    states = opt.resolve_states(args.states)
    mesh_list = opt.resolve_meshes(args.mesh)

    from reference_fem import dolfinx_available

    if not dolfinx_available():
        print("mjed-verify: the UFL oracle needs dolfinx (Debian: apt install python3-dolfinx); run `make demo`.", file=sys.stderr)
        return 3

    # Under mpirun the oracle is distributed over all ranks; rank 0 runs MJED, compares,
    # prints and writes the JSON, and every rank exits with rank 0's code.
    from reference_fem.compat import comm_world

    comm = comm_world()
    if comm.size == 1:
        return _run(args, materials, states, mesh_list, None)
    from reference_fem.distributed import abort_on_error

    with abort_on_error(comm):  # an error on one rank must not leave the others waiting
        code = _run(args, materials, states, mesh_list, comm)
        return comm.bcast(code, root=0)


def _run(args, materials, states, mesh_list, comm) -> int:
    import mjed
    from comparisons.equivalence import FORCE_TOL, STIFFNESS_TOL, format_table, run_cases

    root = comm is None or comm.rank == 0
    t0 = time.perf_counter()
    progress = None if args.quiet else (lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True))
    results = list(run_cases(mesh_list, materials, states, progress=progress, comm=comm))
    if not root:
        return 0  # the exit code is rank 0's (broadcast by the caller)
    elapsed = time.perf_counter() - t0
    ranks = "" if comm is None else f" (oracle on {comm.size} MPI ranks)"
    n_fail = sum(not r.passed for r in results)
    if not args.quiet:
        print(format_table(results))
    worst_f = max(r.force_rel_err for r in results)
    worst_k = max(r.stiffness_rel_err for r in results)
    print(
        f"{len(results) - n_fail}/{len(results)} cases passed (tolerances: force {FORCE_TOL:g}, stiffness {STIFFNESS_TOL:g}); "
        f"worst force error {worst_f:.2e}, worst stiffness error {worst_k:.2e}; {elapsed:.1f} s{ranks}"
    )
    tangent_errors = {}
    ogden = [m for m in materials if m.name == "Ogden"]
    if ogden:
        from comparisons.ogden_tangent import sofa_tangent_errors

        for label, points, cells in mesh_list:
            errs = sofa_tangent_errors(mjed.TetMesh(points, cells), ogden[0], states)
            tangent_errors[label] = errs
            print(f"Ogden, SOFA's coaxial tangent vs the exact one on {label}: "
                  + ", ".join(f"{s} {e:.1e}" for s, e in errs.items()) + " (relative Frobenius; not a pass/fail check)")
    uniaxial = _uniaxial_closed_form(materials, mesh_list)
    n_fail += sum(not row["passed"] for row in uniaxial)
    if args.json:
        payload = {"cases": [r.to_dict() for r in results], "uniaxial_closed_form": uniaxial,
                   "ogden_sofa_tangent_error": tangent_errors}
        if comm is not None:
            payload["mpi_ranks"] = comm.size
        opt.write_json(args.json, payload)
    return 0 if n_fail == 0 else 1


def _uniaxial_closed_form(materials, mesh_list) -> list:
    """The face-reaction check on the selected cube meshes (cube-small if none was selected)."""
    from comparisons.closed_form import has_closed_form, uniaxial_checks

    if not any(has_closed_form(m) for m in materials):
        return []
    cubes = [entry for entry in mesh_list if entry[0].startswith("cube")] or opt.resolve_meshes("cube-small")
    rows = [r for label, points, cells in cubes for r in uniaxial_checks(materials, label, points, cells)]
    worst = max(rows, key=lambda r: r["rel_err"])
    print(f"uniaxial stress closed form (face reaction / current area vs analytic Cauchy sigma_11, stretch 1.3 and 0.8) on "
          f"{', '.join(c[0] for c in cubes)}: {sum(r['passed'] for r in rows)}/{len(rows)} passed; worst {worst['rel_err']:.1e} "
          f"({worst['material']}), worst lateral reaction {max(r['lateral_reaction_rel'] for r in rows):.1e}")
    return rows
