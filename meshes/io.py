"""Reading and writing tetrahedral meshes, with the file's node numbering kept.

Volume meshes read: gmsh ``.msh`` (the legacy format 1.0 with $NOD/$ELM, 2.2 and 4.1; ASCII
files by this package's own reader, which keeps the node tags; binary ones through meshio),
legacy VTK ``.vtk``, VTK XML ``.vtu``, Medit ``.mesh`` and Abaqus ``.inp`` (through meshio).
Surface files (``.stl``, ``.obj``, ``.ply``, ``.off``), and files holding only triangles, are
refused with the gmsh commands that turn a closed surface into a volume mesh.

Reader rules (nothing the user supplied is silently changed):

- node numbering is kept: ``points`` are in file order, *every* node is kept (a node no
  tetrahedron uses stays, with a one-line :class:`MeshReadWarning`), and ``node_ids`` gives
  each node's id in the file's own numbering (gmsh node numbers, Abaqus node labels; Medit
  nodes are numbered 1..n in file order, VTK nodes 0..n-1): ``cells`` index ``points``
  (0-based positions), ``node_ids[cells]`` are the ids written in the file;
- non-tetrahedral cells (triangles, lines, points of a gmsh file) are dropped with a warning
  naming their counts; higher-order tetrahedra are refused (not cut to their corners);
- a cell that repeats a node, a node id that is not defined, an id defined twice: a
  :class:`MeshReadError` naming the file, the cell index and the node ids;
- orientation is not touched: ``mjed.TetMesh(points, cells, fix_orientation=True)`` (the
  ``--fix-orientation`` option of ``mjed-verify liver``) reorders the negatively oriented cells
  and says how many.

Every error message starts with the file's path.
"""

from __future__ import annotations

import os
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional, Union

import numpy as np

from meshes.errors import MeshReadError
from meshes.formats.gmsh_ascii import gmsh_version, read_gmsh_ascii, write_gmsh_legacy
from meshes.formats.raw import RawMesh
from mjed.errors import MeshWarning

__all__ = [
    "TetMeshData",
    "MeshReadWarning",
    "read_mesh",
    "write_mesh",
    "tet_mesh_from_meshio",
    "SUFFIXES",
    "SURFACE_SUFFIXES",
    "surface_advice",
    "one_line_warnings",
]

PathLike = Union[str, os.PathLike]

#: File suffix -> format read (meshio's reader name for the meshio ones).
SUFFIXES: dict[str, str] = {
    ".msh": "gmsh",
    ".vtk": "vtk",
    ".vtu": "vtu",
    ".mesh": "medit",
    ".inp": "abaqus",
}
#: Surface formats: refused with the advice below.
SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off")

# meshio's names of higher-order tetrahedra; a mesh with any of them is refused rather than
# cut down to its corner nodes, which would silently change the discretisation.
_HIGHER_ORDER_TETS = ("tetra10", "tetra20", "tetra35", "tetra56")
_SURFACE_CELLS = ("triangle", "quad", "triangle6", "quad8", "quad9", "polygon")

# How each meshio-read format numbers its nodes (ids = first + position in file order).
_IMPLICIT_NUMBERING = {
    "vtk": (0, "VTK point indices (0-based, file order)"),
    "vtu": (0, "VTK point indices (0-based, file order)"),
    "medit": (1, "Medit vertex numbers (1-based, file order)"),
}


class MeshReadWarning(MeshWarning):
    """Something in a mesh file deserves attention: cells left out, nodes no cell uses."""


def surface_advice(path: Path) -> str:
    """What to do with a surface mesh: the gmsh commands that mesh its inside."""
    stem = path.with_suffix("")
    return (
        "a surface mesh holds no volume: MJED needs linear tetrahedra. Mesh the inside of the "
        "closed surface "
        f'with gmsh: write {stem.name}.geo containing  Merge "{path.name}"; Surface Loop(1) = '
        f"{{1}}; Volume(1) = {{1}};  then run  gmsh {stem.name}.geo -3 -o {stem.name}.msh"
    )


@dataclass(frozen=True)
class TetMeshData:
    """Linear tetrahedra read from a file, numbered as in the file.

    Attributes:
        points: (n, 3) float64 node coordinates in file order, read-only; every node of the
            file is kept, used or not.
        cells: (m, 4) int64 0-based positions into ``points``, read-only, orientation as in
            the file.
        dropped: cell type -> number of non-tetrahedral cells left out, e.g. {"triangle": 12}.
        source: where the mesh came from (the file path).
        node_ids: (n,) int64 id of each node in the file's own numbering.
        numbering: what ``node_ids`` are, in words.
        unused_nodes: (k,) positions of the nodes no tetrahedron uses (kept).
    """

    points: np.ndarray
    cells: np.ndarray
    dropped: dict[str, int] = field(default_factory=dict)
    source: str = ""
    node_ids: Optional[np.ndarray] = None
    numbering: str = "0-based positions"
    unused_nodes: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))

    def __post_init__(self):
        if self.node_ids is None:
            object.__setattr__(self, "node_ids", np.arange(len(self.points), dtype=np.int64))

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def positions_of(self, ids, *, what: str = "node ids") -> np.ndarray:
        """0-based positions (k,) of nodes given by their ids in the file's numbering.

        Raises ValueError naming the first id the file does not define.
        """
        ids = np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(self.node_ids, kind="stable")
        sorted_ids = self.node_ids[order]
        at = np.clip(np.searchsorted(sorted_ids, ids), 0, len(sorted_ids) - 1)
        missing = sorted_ids[at] != ids
        if missing.any():
            raise ValueError(
                f"{what}: {int(ids[missing][0])} is not a node of {self.source or 'the mesh'} "
                f"({self.numbering}: {int(sorted_ids[0])} to {int(sorted_ids[-1])})"
            )
        return order[at]


def _import_meshio():
    try:
        import meshio  # noqa: PLC0415 - optional dependency, imported on first use
    except ImportError as exc:  # pragma: no cover - depends on the machine
        raise ImportError(
            "reading and writing mesh files needs meshio (pip install meshio)"
        ) from exc
    return meshio


def _format_of(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix in SURFACE_SUFFIXES:
        raise MeshReadError(f"{path}: {surface_advice(path)}")
    try:
        return SUFFIXES[suffix]
    except KeyError:
        known = ", ".join(SUFFIXES)
        raise MeshReadError(
            f"{path}: unknown mesh file type {path.suffix or '(no suffix)'!r}; supported volume "
            f"meshes: {known}"
        ) from None


def read_mesh(path: PathLike) -> TetMeshData:
    """Read the linear tetrahedra of a volume mesh file, keeping its node numbering.

    See the module docstring for the formats and the rules. Non-tetrahedral cells are
    dropped, and nodes no tetrahedron uses kept, each with a one-line ``MeshReadWarning``.

    Returns:
        TetMeshData: points (n, 3) in file order, cells (m, 4) positions into points,
        node_ids (n,) as in the file.

    Raises:
        MeshReadError (a ValueError), naming the file: missing file, unknown or surface
            format, unparsable content, no tetrahedra (a surface: with the gmsh commands
            that make a volume mesh), higher-order tetrahedra, 2-D points, undefined or
            repeated node ids, a cell that repeats a node.
    """
    path = Path(path)
    if not path.exists():
        raise MeshReadError(f"{path}: no such file")
    if not path.is_file():
        raise MeshReadError(f"{path}: not a regular file")
    fmt = _format_of(path)
    if fmt == "gmsh" and gmsh_version(path)[1]:
        return tet_mesh_from_raw(read_gmsh_ascii(path), source=str(path))
    meshio = _import_meshio()
    # The format's own reader, not meshio.read: in meshio 5, meshio.read calls sys.exit
    # when parsing fails, and for .msh it also tries the ANSYS reader first.
    reader = getattr(meshio, fmt).read
    try:
        raw = reader(str(path))
    except Exception as exc:  # noqa: BLE001 - meshio raises many types on bad input
        detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise MeshReadError(f"{path}: cannot be read as a {fmt} file ({detail})") from exc
    if fmt == "abaqus":
        ids, numbering = _abaqus_node_labels(path), "Abaqus node labels"
    elif fmt == "gmsh":
        ids, numbering = (
            None,
            "file order, 0-based (binary gmsh read by meshio, which does not keep node tags)",
        )
    else:
        first, numbering = _IMPLICIT_NUMBERING[fmt]
        ids = first + np.arange(len(raw.points), dtype=np.int64)
    return tet_mesh_from_meshio(raw, source=str(path), node_ids=ids, numbering=numbering)


def _abaqus_node_labels(path: Path) -> np.ndarray:
    """The labels of the *NODE lines, in file order (meshio numbers nodes in that order)."""
    labels, inside = [], False
    with open(path, "r", errors="replace") as fh:
        for line in fh:
            text = line.strip()
            if text.startswith("**") or not text:
                continue
            if text.startswith("*"):
                inside = text.split(",")[0].strip().upper() == "*NODE"
                continue
            if inside:
                labels.append(int(text.split(",")[0]))
    return np.array(labels, dtype=np.int64)


def tet_mesh_from_meshio(
    mesh, source: str = "", *, node_ids=None, numbering: str = "0-based positions"
) -> TetMeshData:
    """Keep the linear tetrahedra of a ``meshio.Mesh`` (see ``read_mesh``); all nodes are kept."""
    where = source or "mesh"
    points = np.asarray(mesh.points)
    if points.ndim != 2 or points.shape[1] != 3:
        dims = points.shape[1] if points.ndim == 2 else points.shape
        raise MeshReadError(f"{where}: points have {dims} coordinates, a tetrahedral mesh needs 3")
    ids = (
        np.arange(len(points), dtype=np.int64)
        if node_ids is None
        else np.asarray(node_ids, dtype=np.int64)
    )
    if len(ids) != len(points):
        raise MeshReadError(f"{where}: {len(ids)} node labels for {len(points)} nodes")
    # meshio's cells are positions already; express them as ids for the common path.
    blocks = [(b.type, ids[np.asarray(b.data, dtype=np.int64)]) for b in mesh.cells]
    return tet_mesh_from_raw(
        RawMesh(points.astype(np.float64), ids, numbering, blocks), source=source
    )


def tet_mesh_from_raw(raw: RawMesh, source: str = "") -> TetMeshData:
    """Pick the linear tetrahedra of a RawMesh, map node ids to positions, apply the rules."""
    where = source or "mesh"
    points, ids = np.asarray(raw.points, dtype=np.float64), np.asarray(raw.node_ids, dtype=np.int64)
    if not np.isfinite(points).all():
        bad = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
        raise MeshReadError(
            f"{where}: node {int(ids[bad])} has non-finite coordinates {points[bad].tolist()}"
        )
    uniq, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        raise MeshReadError(
            f"{where}: node id {int(uniq[counts > 1][0])} is defined {int(counts.max())} times"
        )

    counts_by_type: dict[str, int] = {}
    tets = []
    for kind, data in raw.blocks:
        counts_by_type[kind] = counts_by_type.get(kind, 0) + len(data)
        if kind == "tetra":
            tets.append(np.asarray(data, dtype=np.int64).reshape(-1, 4))
    higher = {t: counts_by_type[t] for t in _HIGHER_ORDER_TETS if counts_by_type.get(t)}
    if higher:
        raise MeshReadError(
            f"{where}: higher-order tetrahedra ({_describe(higher)}) are not supported; only "
            "linear 4-node tetrahedra are (re-mesh with element order 1)"
        )
    n_tets = sum(len(b) for b in tets)
    if n_tets == 0:
        found = _describe(counts_by_type) if counts_by_type else "no cells at all"
        advice = ""
        if counts_by_type and set(counts_by_type) <= set(_SURFACE_CELLS) | {"line", "vertex"}:
            advice = "; " + surface_advice(Path(where).with_suffix(".stl")).replace(
                ".stl", ".stl (export the surface)"
            )
        raise MeshReadError(f"{where}: no linear tetrahedra; found {found}{advice}")

    cell_ids = np.concatenate(tets)
    if len(ids) == 0:
        raise MeshReadError(f"{where}: {n_tets} tetrahedra but no nodes")
    order = np.argsort(ids, kind="stable")
    at = np.clip(np.searchsorted(ids[order], cell_ids), 0, len(ids) - 1)
    undefined = ids[order][at] != cell_ids
    if undefined.any():
        k = int(np.flatnonzero(undefined.any(axis=1))[0])
        raise MeshReadError(
            f"{where}: tetrahedron {k} uses node id(s) {cell_ids[k][undefined[k]].tolist()} that "
            "the file does not define"
        )
    cells = order[at].astype(np.int64)
    s = np.sort(cells, axis=1)
    repeats = (s[:, 1:] == s[:, :-1]).any(axis=1)
    if repeats.any():
        k = int(np.flatnonzero(repeats)[0])
        raise MeshReadError(
            f"{where}: tetrahedron {k} repeats a node: its node ids are {cell_ids[k].tolist()} "
            f"({int(repeats.sum())} such cell(s))"
        )

    used = np.zeros(len(points), dtype=bool)
    used[cells.ravel()] = True
    unused = np.flatnonzero(~used)
    dropped = {t: n for t, n in counts_by_type.items() if t != "tetra" and n}
    if dropped:
        warnings.warn(
            f"{where}: kept {n_tets} tetrahedra, dropped {_describe(dropped)}",
            MeshReadWarning,
            stacklevel=3,
        )
    if unused.size:
        warnings.warn(
            f"{where}: {unused.size} node(s) no tetrahedron uses are kept with their numbers (ids "
            f"{ids[unused][:5].tolist()}{' ...' if unused.size > 5 else ''})",
            MeshReadWarning,
            stacklevel=3,
        )
    for a in (points, cells, ids, unused):
        a.setflags(write=False)
    return TetMeshData(points, cells, dropped, source, ids, raw.numbering, unused)


def _describe(counts: dict[str, int]) -> str:
    return ", ".join(f"{n} {t}" for t, n in sorted(counts.items()))


@contextmanager
def one_line_warnings() -> Iterator[None]:
    """Within the block, mesh warnings print as one line ("MeshWarning: message"), without
    the Python file name and source line that ``warnings`` adds by default.
    """
    original = warnings.formatwarning

    def fmt(message, category, filename, lineno, line=None):
        if issubclass(category, MeshWarning):
            return f"{category.__name__}: {message}\n"
        return original(message, category, filename, lineno, line)

    warnings.formatwarning = fmt
    try:
        yield
    finally:
        warnings.formatwarning = original


def write_mesh(
    path: PathLike,
    points: np.ndarray,
    cells: np.ndarray,
    *,
    msh_version: str = "4.1",
    binary: Optional[bool] = None,
) -> Path:
    """Write linear tetrahedra to a .msh, .vtk, .vtu, .mesh (Medit) or .inp (Abaqus) file.

    Args:
        path: the file to write (overwritten); the format follows the suffix.
        points: (n, 3) node coordinates.
        cells: (m, 4) 0-based node indices.
        msh_version: "4.1", "2.2" or "1.0" (gmsh's legacy $NOD/$ELM format), for .msh only.
        binary: binary or text; default text for .msh (exact) and binary for VTK (meshio's
            VTK text output drops digits); Medit and Abaqus files are text.

    Returns:
        the path written.
    """
    path = Path(path)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(
            f"{path}: cannot tell the mesh format from the suffix; use one of {', '.join(SUFFIXES)}"
        )
    pts = np.asarray(points, dtype=np.float64)
    tets = np.asarray(cells)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    if (
        tets.ndim != 2
        or tets.shape[1] != 4
        or (tets.size and (tets.min() < 0 or tets.max() >= len(pts)))
    ):
        raise ValueError(
            f"cells must be (m, 4) indices into the {len(pts)} points, got shape {tets.shape}"
        )
    tets = tets.astype(np.int64)
    if fmt == "gmsh" and msh_version == "1.0":
        return write_gmsh_legacy(path, pts, tets)
    meshio = _import_meshio()

    point_data: dict[str, np.ndarray] = {}
    cell_data: dict[str, list[np.ndarray]] = {}
    kwargs: dict[str, bool] = {}
    if fmt in ("gmsh", "vtk", "vtu"):
        kwargs["binary"] = bool(binary) if binary is not None else fmt != "gmsh"
    if fmt == "gmsh":
        if msh_version not in ("4.1", "2.2"):
            raise ValueError(f"msh_version must be '4.1', '2.2' or '1.0', got {msh_version!r}")
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
