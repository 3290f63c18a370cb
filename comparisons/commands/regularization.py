"""mjed-verify regularization: negative eigenvalues of K and a static solve under compression."""

from __future__ import annotations

from comparisons import options as opt

NAME = "regularization"
ORDER = 20
HELP = "compressed-element regularisation: negative eigenvalues and a Newton + CG static solve"
EXAMPLES = """examples:
  mjed-verify regularization
  mjed-verify regularization --material NeoHookean,Ogden --json reg.json
"""


def configure(parser) -> None:
    opt.add_material_option(parser)
    opt.add_mesh_option(parser, "cube-small", several=False)
    opt.add_json_option(parser)


def run(args) -> int:
    materials = opt.resolve_materials(args.material)
    (label, points, cells), = opt.resolve_meshes(args.mesh, several=False)

    import mjed
    from comparisons.regularization import run_study

    mesh = mjed.TetMesh(points, cells)
    print(f"cube compressed to half its height ({label}, {mesh.n_cells} cells); negative eigenvalues of K at the "
          "homogeneous state, and a static Newton + Jacobi-CG solve in 4 load steps")
    rows = []
    for m in materials:
        out = run_study(mesh, m)
        rows.append(out.to_dict())
        for tag, neg, solve in (("off", out.negative_eigenvalues_off, out.solve_off), ("on ", out.negative_eigenvalues_on, out.solve_on)):
            verdict = (f"solved ({solve.newton_iterations} Newton, {solve.cg_iterations} CG iterations)" if solve.converged
                       else f"FAILED: {solve.message}")
            print(f"  {m.name:18s} regularize {tag}: {neg:4d} negative eigenvalues; {verdict}")
    if args.json:
        opt.write_json(args.json, {"mesh": label, "results": rows})
    return 0
