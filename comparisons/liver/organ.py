"""The user's organ: a mesh by name or file, its length unit, its numbering, its orientation.

Everything the liver study needs to know about the mesh before it simulates: positions in
metres (the mesh's own units times ``scale``), the node ids of the file (so that
``--fixed nodes:FILE`` means the numbers the user sees in gmsh, SOFA or ParaView) and what was
done to it (cells reoriented on request, nodes no cell uses), each reported, none silent.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from common.options import InputError

__all__ = [
    "UNITS",
    "Organ",
    "load_organ",
    "scale_of",
    "fixed_nodes",
    "check_supports",
    "duplicate_nodes",
]

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
    """Positions of the nodes the region specs select, in the file's units and numbering.

    Raises InputError when they select every node: nothing would be left to move.
    """
    from comparisons.liver.regions import select_nodes

    chosen = select_nodes(
        specs, organ.file_points, node_ids=organ.node_ids, numbering=organ.numbering
    )
    if len(chosen) >= organ.mesh.n_nodes:
        raise InputError(
            f"mesh {organ.label}: the fixed region(s) {list(specs)} select every one "
            f"of its {organ.mesh.n_nodes} nodes; nothing would move. Fix only the "
            "supports"
        )
    return chosen


def duplicate_nodes(organ: Organ, limit: int = 5) -> List[Tuple[int, ...]]:
    """Groups of nodes (ids in the file's numbering) at exactly the same position, at most
    ``limit`` groups: two parts meant to be joined but numbered apart.
    """
    pts = np.asarray(organ.file_points)
    _, inverse, counts = np.unique(pts, axis=0, return_inverse=True, return_counts=True)
    groups = []
    for k in np.flatnonzero(counts > 1)[:limit]:
        groups.append(tuple(int(organ.node_ids[i]) for i in np.flatnonzero(inverse.ravel() == k)))
    return groups


def check_supports(
    organ: Organ, fixed: np.ndarray, *, allow_disconnected: bool = False
) -> List[str]:
    """Refuse a mesh that would fall freely in part; return the warnings to report.

    The mesh's cells are split into connected parts (sharing a node). A part with no fixed
    node has rigid-body modes: under gravity it falls for ever, and the run would still
    "pass". Such a part is always refused. Several parts each held are refused too unless
    ``allow_disconnected`` (then a warning says so). Duplicated nodes (same position, other
    ids), the usual cause of an accidental split, are named in both cases.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    cells = np.asarray(organ.mesh.cells)
    n = organ.mesh.n_nodes
    rows = np.repeat(cells[:, :1], 3, axis=1).ravel()
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cells[:, 1:].ravel())), shape=(n, n))
    n_parts, part = connected_components(graph, directed=False)
    used = np.zeros(n, dtype=bool)
    used[cells.ravel()] = True
    parts = np.unique(part[used])  # nodes in no cell are held by the integrator, not a part
    warnings_: List[str] = []
    dups = duplicate_nodes(organ)
    dup_text = ""
    if dups:
        shown = "; ".join(", ".join(str(i) for i in g) for g in dups)
        dup_text = (
            f" Nodes at the same position with different ids ({organ.numbering}): {shown}"
            f"{' (first 5 groups)' if len(dups) == 5 else ''}; merge them to join the "
            "parts."
        )
    if len(parts) <= 1:
        if dups:
            warnings_.append(f"mesh {organ.label}:{dup_text}")
        return warnings_
    held = set(part[np.asarray(fixed, dtype=np.int64)].tolist())
    sizes = {int(p): int(np.count_nonzero(part[used] == p)) for p in parts}
    free = [p for p in parts if p not in held]

    def describe(ps) -> str:
        return ", ".join(
            f"{sizes[int(p)]} nodes around {_centre(organ, part == p)}" for p in ps[:5]
        )

    if free:
        raise InputError(
            f"mesh {organ.label}: {len(parts)} disconnected parts, {len(free)} with "
            f"no fixed node ({describe(free)}): such a part would fall freely "
            f"(rigid-body motion). Fix a node in each part or remove it.{dup_text}"
        )
    text = (
        f"mesh {organ.label}: {len(parts)} disconnected parts, each with fixed nodes "
        f"({describe(parts)})."
    )
    if not allow_disconnected:
        raise InputError(f"{text} Run again with --allow-disconnected if that is meant.{dup_text}")
    warnings_.append(text + dup_text)
    return warnings_


def _centre(organ: Organ, mask: np.ndarray) -> list:
    """The centroid of some nodes in the file's units, for a message."""
    return np.round(np.asarray(organ.file_points)[mask].mean(axis=0), 4).tolist()
