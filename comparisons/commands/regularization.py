"""mjed-verify regularization: negative eigenvalues of K and a static solve under compression."""

from __future__ import annotations

import sys

from common import options as opt

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
    opt.add_allow_incomplete_option(parser)


def run(args) -> int:
    materials = opt.resolve_materials(args.material)
    ((label, points, cells),) = opt.resolve_meshes(args.mesh, several=False)

    from common.terminal import finish
    from comparisons.regularization.study import regularization_study

    progress = lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True)  # noqa: E731
    return finish(regularization_study(label, points, cells, materials, progress=progress), args)
