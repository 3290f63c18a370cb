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

    import mjed
    from comparisons.equivalence import FORCE_TOL, STIFFNESS_TOL, format_table, run_cases

    t0 = time.perf_counter()
    progress = None if args.quiet else (lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True))
    results = list(run_cases(mesh_list, materials, states, progress=progress))
    elapsed = time.perf_counter() - t0
    n_fail = sum(not r.passed for r in results)
    if not args.quiet:
        print(format_table(results))
    worst_f = max(r.force_rel_err for r in results)
    worst_k = max(r.stiffness_rel_err for r in results)
    print(
        f"{len(results) - n_fail}/{len(results)} cases passed (tolerances: force {FORCE_TOL:g}, stiffness {STIFFNESS_TOL:g}); "
        f"worst force error {worst_f:.2e}, worst stiffness error {worst_k:.2e}; {elapsed:.1f} s"
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
    if args.json:
        opt.write_json(args.json, {"cases": [r.to_dict() for r in results], "ogden_sofa_tangent_error": tangent_errors})
    return 0 if n_fail == 0 else 1
