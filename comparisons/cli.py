"""mjed-verify: the command line of the verification suite.

    mjed-verify equivalence --material all --mesh cube-paper --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import List, Optional

__all__ = ["main", "build_parser"]

DEFAULT_MESHES = ("single-tet", "cube-small", "cube-paper")

_EQUIVALENCE_EXAMPLES = """examples:
  mjed-verify equivalence                                  # all materials, built-in meshes, all states
  mjed-verify equivalence --material NeoHookean --mesh cube-small
  mjed-verify equivalence --material all --mesh cube-paper --json eq.json
  mjed-verify equivalence --mesh path/to/organ.msh --states rest,random
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mjed-verify",
        description="Verify a NumPy MJED implementation force by force and stiffness by stiffness against a UFL Galerkin oracle.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    eq = sub.add_parser(
        "equivalence",
        help="compare MJED with the UFL oracle for materials x meshes x states",
        epilog=_EQUIVALENCE_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    eq.add_argument("--material", default="all", help="'all', a material name, or a comma-separated list (default: all)")
    eq.add_argument(
        "--mesh",
        default="all",
        help=f"'all' ({', '.join(DEFAULT_MESHES)}), a built-in mesh name, a mesh file (.msh, .vtk, .vtu), or a comma-separated list",
    )
    eq.add_argument("--states", default="all", help="'all' or a comma-separated list of: rest, uniaxial, compression, shear, triaxial, random")
    eq.add_argument("--json", metavar="PATH", help="write the results as JSON")
    eq.add_argument("--quiet", action="store_true", help="print only the summary line")
    reg = sub.add_parser(
        "regularization",
        help="compressed-element regularisation: negative eigenvalues and a Newton + CG static solve",
        epilog="examples:\n  mjed-verify regularization\n  mjed-verify regularization --material NeoHookean,Ogden --json reg.json\n",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    reg.add_argument("--material", default="all", help="'all', a material name, or a comma-separated list (default: all)")
    reg.add_argument("--mesh", default="cube-small", help="a built-in mesh name or a mesh file (default: cube-small; dense eigenvalues, keep it small)")
    reg.add_argument("--json", metavar="PATH", help="write the results as JSON")
    return parser


def _write_json(path: str, payload: dict) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        json.dump(payload, fh, indent=1)


def _regularization(args) -> int:
    from comparisons.cases import parse_materials
    from comparisons.regularization import run_study
    import mjed

    try:
        materials = parse_materials(args.material)
        (label, points, cells), = _resolve_meshes(args.mesh)
        mesh = mjed.TetMesh(points, cells)
    except (ValueError, OSError) as exc:
        print(f"mjed-verify: error: {exc}", file=sys.stderr)
        return 2
    print(f"cube compressed to half its height ({label}, {mesh.n_cells} cells); negative eigenvalues of K at the "
          "homogeneous state, and a static Newton + Jacobi-CG solve in 4 load steps")
    rows = []
    for m in materials:
        out = run_study(mesh, m)
        rows.append(out.to_dict())
        for tag, neg, solve in (("off", out.negative_eigenvalues_off, out.solve_off), ("on ", out.negative_eigenvalues_on, out.solve_on)):
            verdict = f"solved ({solve.newton_iterations} Newton, {solve.cg_iterations} CG iterations)" if solve.converged else f"FAILED: {solve.message}"
            print(f"  {m.name:18s} regularize {tag}: {neg:4d} negative eigenvalues; {verdict}")
    if args.json:
        _write_json(args.json, {"mesh": label, "results": rows})
    return 0


def _resolve_meshes(spec: str) -> list:
    import meshes

    names = DEFAULT_MESHES if spec.strip().lower() == "all" else [s.strip() for s in spec.split(",") if s.strip()]
    out = []
    for name in names:
        points, cells, label = meshes.resolve(name)
        out.append((label, points, cells))
    return out


def _resolve_states(spec: str) -> List[str]:
    from comparisons.states import state_names

    if spec.strip().lower() == "all":
        return list(state_names())
    names = [s.strip() for s in spec.split(",") if s.strip()]
    unknown = [n for n in names if n not in state_names()]
    if unknown or not names:
        raise ValueError(f"unknown state(s) {unknown}; known states: {', '.join(state_names())}")
    return names


def _equivalence(args) -> int:
    from comparisons.cases import parse_materials
    from comparisons.equivalence import FORCE_TOL, STIFFNESS_TOL, format_table, run_cases

    import mjed

    # Refuse bad input before any work starts, with a message and no traceback.
    try:
        materials = parse_materials(args.material)
        states = _resolve_states(args.states)
        mesh_list = _resolve_meshes(args.mesh)
        for label, points, cells in mesh_list:
            mjed.TetMesh(points, cells)  # raises MeshError naming the problem
    except (ValueError, OSError) as exc:
        print(f"mjed-verify: error: {exc}", file=sys.stderr)
        return 2

    from reference_fem import dolfinx_available

    if not dolfinx_available():
        print("mjed-verify: the UFL oracle needs dolfinx (Debian: apt install python3-dolfinx); run `make demo`.", file=sys.stderr)
        return 3

    import logging

    logging.disable(logging.INFO)  # FFCx's JIT logs every compilation at INFO
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
    ogden = [m for m in materials if m.name == "Ogden"]
    tangent_errors = {}
    if ogden:
        from comparisons.ogden_tangent import sofa_tangent_errors

        for label, points, cells in mesh_list:
            errs = sofa_tangent_errors(mjed.TetMesh(points, cells), ogden[0], states)
            tangent_errors[label] = errs
            print(f"Ogden, SOFA's coaxial tangent vs the exact one on {label}: "
                  + ", ".join(f"{s} {e:.1e}" for s, e in errs.items()) + " (relative Frobenius; not a pass/fail check)")
    if args.json:
        payload = {"cases": [r.to_dict() for r in results], "ogden_sofa_tangent_error": tangent_errors}
        _write_json(args.json, payload)
    return 0 if n_fail == 0 else 1


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "equivalence":
        return _equivalence(args)
    if args.command == "regularization":
        return _regularization(args)
    parser.error(f"unknown command {args.command}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
