"""Options and input checks shared by every mjed-verify subcommand.

Every subcommand spells --material, --mesh, --states, --json and --out the same way, and
refuses bad input before any work starts by raising :class:`InputError`; the CLI turns it into
one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
from typing import List, Sequence, Tuple

import numpy as np

__all__ = [
    "InputError",
    "DEFAULT_MESHES",
    "add_material_option",
    "add_mesh_option",
    "add_states_option",
    "add_json_option",
    "add_out_option",
    "resolve_materials",
    "resolve_meshes",
    "resolve_states",
    "write_json",
    "strict_json",
    "check_writable_destination",
    "add_allow_incomplete_option",
]

#: The built-in meshes that 'all' stands for in the equivalence study.
DEFAULT_MESHES = ("single-tet", "cube-small", "cube-paper")


class InputError(ValueError):
    """Bad user input, found before any work started."""


def add_material_option(parser: argparse.ArgumentParser, default: str = "all") -> None:
    parser.add_argument(
        "--material",
        default=default,
        help=f"'all', a material name, or a comma-separated list (default: {default})",
    )


def add_mesh_option(parser: argparse.ArgumentParser, default: str, *, several: bool = True) -> None:
    what = "a built-in mesh name, a mesh file (.msh, .vtk, .vtu)"
    if several:
        what = f"'all' ({', '.join(DEFAULT_MESHES)}), {what}, or a comma-separated list"
    parser.add_argument("--mesh", default=default, help=f"{what} (default: {default})")


def add_states_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--states",
        default="all",
        help="'all' or a comma-separated list of: rest, uniaxial, compression, shear, triaxial, "
        "random",
    )


def add_json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")


def add_out_option(parser: argparse.ArgumentParser, default: str) -> None:
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=default,
        help=f"directory for figures and tables (default: {default})",
    )


def resolve_materials(spec: str):
    from common.cases import parse_materials

    try:
        return parse_materials(spec)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def resolve_meshes(spec: str, *, several: bool = True) -> List[Tuple[str, np.ndarray, np.ndarray]]:
    """Mesh names or paths -> [(label, points, cells)], each checked by mjed.TetMesh."""
    import meshes
    import mjed

    text = spec.strip()
    if several and text.lower() == "all":
        names: Sequence[str] = DEFAULT_MESHES
    else:
        names = [s.strip() for s in text.split(",") if s.strip()] if several else [text]
    if not names:
        raise InputError("no mesh given")
    out = []
    for name in names:
        try:
            points, cells, label = meshes.resolve(name)
            mjed.TetMesh(points, cells)  # raises MeshError naming the problem
        except (ValueError, OSError) as exc:
            raise InputError(str(exc)) from None
        out.append((label, points, cells))
    return out


def resolve_states(spec: str) -> List[str]:
    from common.states import state_names

    if spec.strip().lower() == "all":
        return list(state_names())
    names = [s.strip() for s in spec.split(",") if s.strip()]
    unknown = [n for n in names if n not in state_names()]
    if unknown or not names:
        raise InputError(f"unknown state(s) {unknown}; known states: {', '.join(state_names())}")
    return names


def check_writable_destination(path: str, *, is_dir: bool) -> None:
    """Refuse, before any work, a --json file or --out directory that cannot be written."""
    target = os.path.abspath(path)
    folder = target if is_dir else os.path.dirname(target)
    if not is_dir and os.path.isdir(target):
        raise InputError(f"{path}: is a directory, expected a file name for the JSON")
    probe = folder
    while not os.path.exists(probe):  # the nearest existing ancestor decides
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    try:  # a real write, not os.access: root passes access checks on read-only mounts
        if not os.path.isdir(probe):
            raise OSError("not a directory")
        tempfile.TemporaryFile(dir=probe).close()
    except OSError:
        raise InputError(
            f"{path}: cannot write there ({probe} is not a writable directory)"
        ) from None


def write_json(path: str, payload: dict) -> None:
    """Write strict JSON (see :func:`strict_json`), creating the directory (reports/ is not in a
    fresh clone).
    """
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        json.dump(strict_json(payload), fh, indent=1, allow_nan=False)


#: At most this many non-finite values are listed one by one in "non_finite".
_MAX_NOTES = 100


def strict_json(payload: dict) -> dict:
    """A copy of ``payload`` that any JSON parser reads: NaN and infinities (which Python would
    write as the non-standard ``NaN`` and ``Infinity``) become null, and a top-level
    ``"non_finite"`` list says where each was and what it was, e.g.
    ``{"path": "data/runs/0/fps", "value": "inf"}``. NumPy scalars and arrays become numbers and
    lists; any other object its text.
    """
    notes: List[dict] = []
    count = [0]

    def clean(obj, path: str):
        if isinstance(obj, dict):
            return {str(k): clean(v, f"{path}/{k}" if path else str(k)) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [clean(v, f"{path}/{i}") for i, v in enumerate(obj)]
        if hasattr(obj, "tolist"):  # NumPy arrays and scalars
            return clean(obj.tolist(), path)
        if isinstance(obj, bool) or obj is None or isinstance(obj, (int, str)):
            return obj
        if isinstance(obj, float):
            if math.isfinite(obj):
                return obj
            count[0] += 1
            if len(notes) < _MAX_NOTES:
                notes.append({"path": path, "value": repr(obj)})
            return None
        return str(obj)

    out = clean(payload, "")
    if count[0]:
        if count[0] > len(notes):
            notes.append({"path": "...", "value": f"{count[0] - len(notes)} more not listed"})
        out["non_finite"] = notes
    return out


def add_allow_incomplete_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="exit with 0 instead of 3 when a target was missed, a study did not run or the run "
        "was partial (a failed check still exits with 1)",
    )
