"""The user's organ: a mesh by name or file, its length unit, its numbering, its orientation.

Everything the liver study needs to know about the mesh before it simulates: positions in
metres (the mesh's own units times ``scale``), the node ids of the file (so that
``--fixed nodes:FILE`` means the numbers the user sees in gmsh, SOFA or ParaView) and what was
done to it (cells reoriented on request, nodes no cell uses), each reported, none silent.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from common.options import InputError

__all__ = ["UNITS", "Organ", "load_organ", "scale_of"]

#: Length units accepted by --units, as metres per unit.
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


def scale_of(units: Optional[str] = None, scale: Optional[float] = None) -> float:
    """Metres per mesh unit from --units or --scale (not both); 1 when neither is given."""
    if units is not None and scale is not None:
        raise InputError("give --units or --scale, not both")
    if units is not None:
        try:
            return UNITS[units]
        except KeyError:
            raise InputError(
                f"unknown unit {units!r}; use one of {', '.join(UNITS)} (or --scale)"
            ) from None
    if scale is None:
        return 1.0
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"--scale must be finite and > 0 (metres per mesh unit), got {scale!r}")
    return float(scale)


@dataclass(frozen=True)
class Organ:
    """A mesh ready for the simulation.

    mesh: mjed.TetMesh in metres. label: catalog name or path. file_points: (n, 3) the
    coordinates in the file's units (what region specs refer to). node_ids: (n,) ids in the
    file's numbering; numbering: what they are. scale: metres per file unit. reoriented:
    cells whose orientation was fixed (only with fix_orientation). unused_nodes: positions of
    nodes no cell uses (kept, held by the integrator).
    """

    mesh: object
    label: str
    file_points: np.ndarray
    node_ids: np.ndarray
    numbering: str
    scale: float
    reoriented: int
    unused_nodes: np.ndarray

    def describe(self) -> str:
        notes = [
            f"{self.mesh.n_nodes} nodes, {self.mesh.n_cells} cells",
            f"{self.scale:g} m per mesh unit",
        ]
        if self.reoriented:
            notes.append(f"{self.reoriented} cell(s) reoriented (--fix-orientation)")
        if len(self.unused_nodes):
            notes.append(f"{len(self.unused_nodes)} node(s) in no cell, held in place")
        return f"{self.label} ({', '.join(notes)})"


def load_organ(
    mesh_spec: Union[str, Tuple], *, scale: float = 1.0, fix_orientation: bool = False
) -> Organ:
    """Load a catalog mesh, a mesh file or (points, cells[, label]) for the liver study.

    Raises:
        InputError: unknown name, unreadable file, no tetrahedra, invalid cells; negatively
            oriented cells name the --fix-orientation option that reorders them.
    """
    import meshes
    import mjed
    from meshes.io import read_mesh

    numbering, ids = "0-based positions", None
    if isinstance(mesh_spec, tuple):
        points, cells, label = (*mesh_spec, "given")[:3]
    elif mesh_spec in meshes.names():
        points, cells = meshes.load(mesh_spec)
        label = mesh_spec
    else:
        try:
            data = read_mesh(mesh_spec)
        except (ValueError, OSError) as exc:
            raise InputError(str(exc)) from None
        points, cells, label, ids, numbering = (
            data.points,
            data.cells,
            str(mesh_spec),
            data.node_ids,
            data.numbering,
        )
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells)
    if cells.ndim != 2 or len(cells) == 0:
        raise InputError(f"mesh {label}: no volume (tetrahedral) cells")
    ids = np.arange(len(points), dtype=np.int64) if ids is None else np.asarray(ids)
    with warnings.catch_warnings():
        # TetMesh's own warnings (reorientation, unused nodes) are reported through Organ.describe.
        warnings.simplefilter("ignore", mjed.MeshWarning)
        try:
            mesh = mjed.TetMesh(points * scale, cells, fix_orientation=fix_orientation)
        except ValueError as exc:
            text = str(exc)
            if "negatively oriented" in text:  # name the option the command line has
                text = (
                    text.split(" Pass fix_orientation")[0]
                    + " Run again with --fix-orientation to swap two nodes of each such cell (the "
                    "number reordered is reported)."
                )
            raise InputError(f"mesh {label}: {text}") from None
    return Organ(
        mesh, label, points, ids, numbering, scale, mesh.n_reoriented, mesh.unreferenced_nodes
    )


def fixed_nodes(organ: Organ, specs: Sequence[str]) -> np.ndarray:
    """Positions of the nodes the region specs select, in the file's units and numbering."""
    from comparisons.regions import select_nodes

    return select_nodes(
        specs, organ.file_points, node_ids=organ.node_ids, numbering=organ.numbering
    )
