"""Reading and writing tetrahedral meshes through meshio.

Supported files: gmsh ``.msh`` (2.2 ASCII and binary, 4.1), legacy VTK ``.vtk`` and VTK XML
``.vtu``. Only linear 4-node tetrahedra are kept. The reader does not touch orientation:
``mjed.TetMesh(points, cells, fix_orientation=...)`` decides what to do with it.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import numpy as np

from meshes.errors import MeshReadError
from meshes.tetra import remove_unreferenced

__all__ = ["TetMeshData", "MeshReadWarning", "read_mesh", "write_mesh", "tet_mesh_from_meshio", "SUFFIXES"]

PathLike = Union[str, os.PathLike]

#: File suffix -> meshio format (also the name of meshio's reader submodule).
SUFFIXES: dict[str, str] = {".msh": "gmsh", ".vtk": "vtk", ".vtu": "vtu"}

# meshio's names of higher-order tetrahedra; a mesh with any of them is refused rather than
# cut down to its corner nodes, which would silently change the discretisation.
_HIGHER_ORDER_TETS = ("tetra10", "tetra20", "tetra35", "tetra56")


class MeshReadWarning(UserWarning):
    """Something in a mesh file was left out (non-tetrahedral cells)."""


@dataclass(frozen=True)
class TetMeshData:
    """Linear tetrahedra read from a file.

    Attributes:
        points: (n, 3) float64 node coordinates, read-only; every node is used by a cell.
        cells: (m, 4) int64 node indices, 0-based, read-only, orientation as in the file.
        dropped: cell type -> number of non-tetrahedral cells left out, e.g. {"triangle": 12}.
        source: where the mesh came from (the file path).
        unreferenced_removed: nodes removed because no tetrahedron used them.
    """

    points: np.ndarray
    cells: np.ndarray
    dropped: dict[str, int] = field(default_factory=dict)
    source: str = ""
    unreferenced_removed: int = 0

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_cells(self) -> int:
        return len(self.cells)


def _import_meshio():
    try:
        import meshio  # noqa: PLC0415 - optional dependency, imported on first use
    except ImportError as exc:  # pragma: no cover - depends on the machine
        raise ImportError("reading and writing mesh files needs meshio (pip install meshio)") from exc
    return meshio


def _format_of(path: Path) -> str:
    try:
        return SUFFIXES[path.suffix.lower()]
    except KeyError:
        known = ", ".join(SUFFIXES)
        raise MeshReadError(
            f"{path}: unknown mesh file type {path.suffix or '(no suffix)'!r}; supported: {known}"
        ) from None


def read_mesh(path: PathLike) -> TetMeshData:
    """Read the linear tetrahedra of a .msh, .vtk or .vtu file.

    Non-tetrahedral cells (vertices, lines, triangles, hexahedra, ...) are dropped with a
    ``MeshReadWarning`` naming their counts; nodes left unused are removed and the rest
    renumbered in file order.

    Args:
        path: the file.

    Returns:
        TetMeshData with points (n, 3) and cells (m, 4).

    Raises:
        MeshReadError: the file is missing, has an unknown suffix, cannot be parsed, holds
            no tetrahedra or higher-order (e.g. 10-node) tetrahedra, or has 2-D points.
    """
    path = Path(path)
    if not path.exists():
        raise MeshReadError(f"{path}: no such file")
    if not path.is_file():
        raise MeshReadError(f"{path}: not a regular file")
    fmt = _format_of(path)
    meshio = _import_meshio()
    # The format's own reader, not meshio.read: in meshio 5, meshio.read calls sys.exit
    # when parsing fails, and for .msh it also tries the ANSYS reader first.
    reader = getattr(meshio, fmt).read
    try:
        raw = reader(str(path))
    except Exception as exc:  # noqa: BLE001 - meshio raises many types on bad input
        detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise MeshReadError(f"{path}: cannot be read as a {fmt} file ({detail})") from exc
    return tet_mesh_from_meshio(raw, source=str(path))


def tet_mesh_from_meshio(mesh, source: str = "") -> TetMeshData:
    """Keep the linear tetrahedra of a ``meshio.Mesh`` (see ``read_mesh``)."""
    where = source or "mesh"
    points = np.asarray(mesh.points)
    if points.ndim != 2 or points.shape[1] != 3:
        dims = points.shape[1] if points.ndim == 2 else points.shape
        raise MeshReadError(f"{where}: points have {dims} coordinates, a tetrahedral mesh needs 3")

    counts: dict[str, int] = {}
    blocks = []
    for block in mesh.cells:
        data = np.asarray(block.data)
        counts[block.type] = counts.get(block.type, 0) + len(data)
        if block.type == "tetra":
            blocks.append(data.reshape(-1, 4))
    higher = {t: counts[t] for t in _HIGHER_ORDER_TETS if counts.get(t)}
    if higher:
        raise MeshReadError(
            f"{where}: higher-order tetrahedra ({_describe(higher)}) are not supported; "
            "only linear 4-node tetrahedra are (re-mesh with element order 1)"
        )
    n_tets = sum(len(b) for b in blocks)
    if n_tets == 0:
        found = _describe(counts) if counts else "no cells at all"
        raise MeshReadError(f"{where}: no linear tetrahedra; found {found}")

    cells = np.concatenate(blocks).astype(np.int64)
    if cells.min() < 0 or cells.max() >= len(points):
        raise MeshReadError(f"{where}: tetrahedron node indices outside [0, {len(points)})")
    points, cells, removed = remove_unreferenced(points.astype(np.float64), cells)
    if not np.isfinite(points).all():
        raise MeshReadError(f"{where}: non-finite node coordinates")

    dropped = {t: n for t, n in counts.items() if t != "tetra" and n}
    if dropped:
        warnings.warn(
            f"{where}: kept {n_tets} tetrahedra, dropped {_describe(dropped)}"
            + (f" and {removed} node(s) no tetrahedron uses" if removed else ""),
            MeshReadWarning,
            stacklevel=3,
        )
    points.setflags(write=False)
    cells.setflags(write=False)
    return TetMeshData(points, cells, dropped, source, removed)


def _describe(counts: dict[str, int]) -> str:
    return ", ".join(f"{n} {t}" for t, n in sorted(counts.items()))


def write_mesh(
    path: PathLike,
    points: np.ndarray,
    cells: np.ndarray,
    *,
    msh_version: str = "4.1",
    binary: Optional[bool] = None,
) -> Path:
    """Write linear tetrahedra to a .msh, .vtk or .vtu file (format from the suffix).

    Args:
        path: the file to write (overwritten).
        points: (n, 3) node coordinates.
        cells: (m, 4) 0-based node indices.
        msh_version: "4.1" or "2.2", for .msh files only.
        binary: binary or text; default text for .msh (exact, %.16e) and binary for VTK
            (meshio's VTK text output drops digits).

    Returns:
        the path written.
    """
    path = Path(path)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: cannot tell the mesh format from the suffix; use one of {', '.join(SUFFIXES)}")
    pts = np.asarray(points, dtype=np.float64)
    tets = np.asarray(cells)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4 or (tets.size and (tets.min() < 0 or tets.max() >= len(pts))):
        raise ValueError(f"cells must be (m, 4) indices into the {len(pts)} points, got shape {tets.shape}")
    tets = tets.astype(np.int64)
    meshio = _import_meshio()

    point_data: dict[str, np.ndarray] = {}
    cell_data: dict[str, list[np.ndarray]] = {}
    kwargs: dict[str, bool] = {"binary": bool(binary) if binary is not None else fmt != "gmsh"}
    if fmt == "gmsh":
        if msh_version not in ("4.1", "2.2"):
            raise ValueError(f"msh_version must be '4.1' or '2.2', got {msh_version!r}")
        # Everything in volume entity 1, physical group 1. Without these tags meshio 5
        # prints warnings (2.2) or writes a 4.1 file that gmsh itself cannot open.
        ones = np.ones(len(tets), dtype=np.int64)
        cell_data = {"gmsh:physical": [ones], "gmsh:geometrical": [ones]}
        if msh_version == "4.1":
            point_data = {"gmsh:dim_tags": np.tile(np.array([3, 1], dtype=np.int64), (len(pts), 1))}
        fmt = "gmsh" if msh_version == "4.1" else "gmsh22"
    out = meshio.Mesh(pts, [("tetra", tets)], point_data=point_data, cell_data=cell_data)
    meshio.write(str(path), out, file_format=fmt, **kwargs)
    return path
