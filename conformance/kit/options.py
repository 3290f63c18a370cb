"""Command-line options shared by ``mjed-verify export`` and ``mjed-verify check``: the models
(--material, --energy/--param/--fibre), meshes and states, turned into kit cases.
"""

from __future__ import annotations

from typing import List

from common import options as opt
from common.options import InputError

__all__ = ["add_model_options", "resolve_models", "cases_from_args"]


def add_model_options(parser, *, material_default: str = "all") -> None:
    parser.add_argument(
        "--material",
        default=None,
        help=f"'all', a material name or a comma-separated list (default: {material_default} "
        "unless --energy is given)",
    )
    parser.add_argument(
        "--energy",
        metavar="EXPR",
        help="a strain energy of I1, I2, I3, J, I1b, I2b, I4, I5, C11..C33, E11..E33 and "
        "parameters, e.g. 'mu/2*(I1b-3) + K/2*(J-1)**2' (docs/conventions.md, 'User energies')",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a parameter of --energy (repeat for each)",
    )
    parser.add_argument(
        "--fibre",
        metavar="X,Y,Z",
        help="one fibre direction for I4 and I5 in every cell (default: the mesh's helical frame "
        "field, one fibre per cell, as for Costa; docs/conventions.md, 'Fibre frames')",
    )
    opt.add_mesh_option(parser, "single-tet")
    opt.add_states_option(parser)


def resolve_models(args, *, material_default: str = "all") -> list:
    models: list = []
    if args.material is not None or args.energy is None:
        models.extend(opt.resolve_materials(args.material or material_default))
    if args.energy is not None:
        from reference_fem.user_energy import user_energy_from_cli

        try:
            models.append(user_energy_from_cli(args.energy, args.param, args.fibre, name="energy"))
        except ValueError as exc:
            raise InputError(f"--energy: {exc}") from None
    elif args.param or args.fibre:
        raise InputError("--param and --fibre need --energy")
    return models


def cases_from_args(args, *, probes: int) -> List:
    from conformance.kit.cases import build_cases

    models = resolve_models(args)
    meshes = opt.resolve_meshes(args.mesh)
    states = opt.resolve_states(args.states)
    try:
        return build_cases(models, meshes, states, probes=probes)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def reproduce(name: str, args, positional: str = "") -> str:
    """The command line that reproduces this run, from the parsed options."""
    import shlex

    words = ["mjed-verify", name] + ([positional] if positional else [])
    for key, flag in (
        ("material", "--material"),
        ("energy", "--energy"),
        ("fibre", "--fibre"),
        ("mesh", "--mesh"),
        ("states", "--states"),
        ("engine_command", "--command"),
        ("timeout", "--timeout"),
    ):
        value = getattr(args, key, None)
        from_kit = (
            name == "check" and positional and key in ("mesh", "states")
        )  # the kit's manifest decides
        if (
            value is not None
            and not from_kit
            and not (key == "timeout" and getattr(args, "engine_command", None) is None)
        ):
            words += [flag, str(value)]
    for p in getattr(args, "param", []) or []:
        words += ["--param", p]
    return " ".join(shlex.quote(w) for w in words)
