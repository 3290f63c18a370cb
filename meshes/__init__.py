"""Tetrahedral meshes for the MJED verification suite: generators, built-ins and file I/O.

Every mesh is a pair ``(points, cells)``: points (n, 3) float64 and cells (m, 4) int64 of
linear tetrahedra with 0-based node numbers. Generated and built-in meshes are positively
oriented; meshes read from files keep the file's orientation (``mjed.TetMesh`` fixes it
on request).

gmsh is needed only to generate meshes, meshio only to read and write files.
"""

from __future__ import annotations

from typing import Any

from meshes.errors import MeshReadError
from meshes.generate import cylinder, single_tetrahedron, unit_cube
from meshes.io import MeshReadWarning, TetMeshData, read_mesh, write_mesh
from meshes.tetra import orient_positively, remove_unreferenced, signed_volumes

__all__ = [
    "CatalogEntry",
    "MeshReadError",
    "MeshReadWarning",
    "TetMeshData",
    "cylinder",
    "describe",
    "load",
    "names",
    "orient_positively",
    "read_mesh",
    "remove_unreferenced",
    "resolve",
    "signed_volumes",
    "single_tetrahedron",
    "unit_cube",
    "write_mesh",
]

# The catalog is imported on first use rather than here, so that
# `python -m meshes.catalog` does not find the module already imported (runpy warns).
_CATALOG_NAMES = ("CatalogEntry", "describe", "load", "names", "resolve")


def __getattr__(name: str) -> Any:
    if name in _CATALOG_NAMES:
        from meshes import catalog  # noqa: PLC0415

        return getattr(catalog, name)
    raise AttributeError(f"module 'meshes' has no attribute {name!r}")
