"""What the SOFA study checks and times: force fields, the materials each offers, the meshes.

The materials are the project's declarations that name a SOFA law (``Declaration.sofa``);
Costa is checked as its energy written in the global axes (SOFA's Costa reads no frame), with
the case read back as Costa by the adapter. The meshes: ``single-tet`` and ``cube-paper``
(the paper's cube), three hard meshes of the checker's corpus (a cap, a sliver in mm, a
mesh graded over 6.7 orders of volume) written as VTK XML, and the SofaMJEDFEM plugin's own
example meshes (``examples/data/cylinder*.vtk``) when their folder is given.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import List, Optional, Tuple

__all__ = [
    "FORCEFIELDS",
    "check_meshes",
    "costa_energy_options",
    "environment_with_program",
    "sofa_materials",
    "states_for",
]

#: The engine program's force fields, in the order the report lists them.
FORCEFIELDS = ("mjed", "hyperelasticity", "standard")


def sofa_materials() -> List[str]:
    """Names of the declared materials that have a SOFA law, Costa last."""
    from mjed.materials.sofa import sofa_parameter_order

    names = [cls.__name__ for cls, _ in sofa_parameter_order().values()]
    return sorted(names, key=lambda n: (n == "Costa", names.index(n)))


def costa_energy_options() -> List[str]:
    """``check`` options giving Costa's default parameters as its global-axes energy."""
    from common.cases import default_material
    from conformance.adapters.sofa.mapping import costa_in_global_axes

    m = default_material("Costa")
    values = {f.name: getattr(m, f.name) for f in dataclasses.fields(m)}
    expression, parameters = costa_in_global_axes(values)
    options = ["--energy", expression]
    for name, value in parameters.items():
        options += ["--param", f"{name}={value!r}"]
    return options


def check_meshes(folder: Path, plugin_meshes: Optional[Path], quick: bool) -> List[Tuple[str, str]]:
    """(label, --mesh argument) pairs: built-ins, hard meshes written into ``folder``, and the
    plugin's cylinders (every ``cylinder*.vtk`` of ``plugin_meshes``).
    """
    from conformance.corpus import corpus_meshes
    from meshes import write_mesh

    out = [("single-tet", "single-tet"), ("cube-small" if quick else "cube-paper",) * 2]
    for mesh in corpus_meshes(small=True):
        path = folder / f"{mesh.label}.vtu"
        write_mesh(path, mesh.points, mesh.cells)
        out.append((mesh.label, str(path)))
    if plugin_meshes is not None:
        found = sorted(Path(plugin_meshes).glob("cylinder*.vtk"))
        if not found:
            raise FileNotFoundError(
                f"{plugin_meshes}: no cylinder*.vtk (SofaMJEDFEM's examples/data)"
            )
        out += [(p.stem, str(p)) for p in (found[:1] if quick else found)]
    return out


def states_for(label: str) -> str:
    """Every state on the small meshes; on the others the states that load every term. The
    hard meshes leave ``random`` out: its unbounded stretch on a cap or a sliver overflows the
    exponential energies in float64 for every engine, the oracle included (the corpus bounds
    its own random states for that reason).
    """
    if label in ("single-tet", "cube-small"):
        return "all"
    if label in ("cap-SI", "sliver-mm", "graded-SI"):
        return "uniaxial,shear,triaxial"
    return "uniaxial,shear,triaxial,random"


def environment_with_program(program: os.PathLike) -> dict:
    env = dict(os.environ)
    env["MJED_SOFA_ENGINE"] = str(program)
    return env
