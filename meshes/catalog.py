"""Named built-in meshes.

The unstructured meshes are committed under ``meshes/data`` so that loading them needs
neither gmsh nor a particular gmsh version; ``load`` regenerates a mesh with gmsh only when
its file is missing. Rebuild the committed files with::

    python -m meshes.catalog --regenerate
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Optional, Sequence, Union

import numpy as np

from meshes.generate import single_tetrahedron, unit_cube
from meshes.io import SUFFIXES, read_mesh, write_mesh
from meshes.liver import liver

__all__ = [
    "CatalogEntry",
    "names",
    "describe",
    "load",
    "resolve",
    "regenerate",
    "check_counts",
    "DATA_DIR",
]

DATA_DIR = Path(__file__).resolve().parent / "data"

Mesh = tuple[np.ndarray, np.ndarray]

# Volumes of the committed liver meshes (sum of their cell volumes, m^3).
LIVER_VOLUME = 0.0026228471254736785
LIVER_COARSE_VOLUME = 0.002521563071231272
LIVER_100K_VOLUME = 0.00264942196438805


@dataclass(frozen=True)
class CatalogEntry:
    """One built-in mesh.

    Attributes:
        name: catalog name.
        description: one line for listings and reports.
        filename: file under ``DATA_DIR``, or None for meshes built in code.
        domain_volume: exact volume of the meshed domain (the cell volumes sum to it).
        build: function that generates the mesh (gmsh for the unstructured ones).
        expected_cells: (count, relative tolerance) the mesh must meet, if any.
        expected_nodes: (count, relative tolerance) the mesh must meet, if any.
    """

    name: str
    description: str
    filename: Optional[str]
    domain_volume: float
    build: Callable[[], Mesh]
    expected_cells: Optional[tuple[int, float]] = None
    expected_nodes: Optional[tuple[int, float]] = None


_ENTRIES: tuple[CatalogEntry, ...] = (
    CatalogEntry(
        "single-tet",
        "the reference tetrahedron (0,0,0), e_x, e_y, e_z",
        None,
        1.0 / 6.0,
        single_tetrahedron,
    ),
    CatalogEntry(
        "cube-small",
        "unit cube, ~500 Delaunay tetrahedra",
        "cube-small.msh",
        1.0,
        lambda: unit_cube(500),
        expected_cells=(500, 0.05),
    ),
    CatalogEntry(
        "cube-medium",
        "unit cube, ~3,000 Delaunay tetrahedra",
        "cube-medium.msh",
        1.0,
        lambda: unit_cube(3000),
        expected_cells=(3000, 0.05),
    ),
    # The paper's cube: ~20,700 tetrahedra on ~4,300 nodes. gmsh's Delaunay mesh of the
    # cube has ~4.75 cells per node at this size, so matching the cell count puts the
    # node count within about 1 % as well.
    CatalogEntry(
        "cube-paper",
        "unit cube of the paper, ~20,700 tetrahedra and ~4,300 nodes",
        "cube-paper.npz",
        1.0,
        lambda: unit_cube(20700),
        expected_cells=(20700, 0.05),
        expected_nodes=(4300, 0.05),
    ),
    # Liver-shaped organ (meshes/liver.py) at the paper's size, 1,240 vertices and 5,000
    # tetrahedra, and a coarse one for CI. The domain is the union of the tetrahedra (the
    # surface is curved), so domain_volume is the committed mesh's own volume.
    CatalogEntry(
        "liver",
        "liver-shaped organ (metres), ~5,000 tetrahedra and ~1,240 nodes like the paper's",
        "liver.npz",
        LIVER_VOLUME,
        lambda: liver(5000),
        expected_cells=(5000, 0.05),
        expected_nodes=(1240, 0.05),
    ),
    # The same organ at about 100,000 tetrahedra (18,827 nodes): the GPU's scale
    # (scripts/gpu_session.sh runs the liver study on it). Committed (1.4 MB), so that a
    # machine without gmsh loads it.
    CatalogEntry(
        "liver-100k",
        "liver-shaped organ (metres), ~100,000 tetrahedra and ~18,800 nodes, for the GPU",
        "liver-100k.npz",
        LIVER_100K_VOLUME,
        lambda: liver(100_000),
        expected_cells=(100_000, 0.05),
    ),
    CatalogEntry(
        "liver-coarse",
        "liver-shaped organ (metres), ~600 tetrahedra, for CI",
        "liver-coarse.npz",
        LIVER_COARSE_VOLUME,
        lambda: liver(600),
        expected_cells=(600, 0.05),
    ),
)
_BY_NAME = {e.name: e for e in _ENTRIES}


def names() -> tuple[str, ...]:
    """Names of the built-in meshes, smallest first."""
    return tuple(_BY_NAME)


def describe(name: str) -> CatalogEntry:
    """The catalog entry of a built-in mesh; ValueError listing the names if unknown."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise ValueError(
            f"unknown built-in mesh {name!r}; valid names: {', '.join(names())}"
        ) from None


def _read_file(path: Path) -> Mesh:
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            return np.array(data["points"], dtype=np.float64), np.array(
                data["cells"], dtype=np.int64
            )
    data = read_mesh(path)
    return np.array(data.points), np.array(data.cells)


def load(name: str) -> Mesh:
    """Points (n, 3) float64 and cells (m, 4) int64 of a built-in mesh.

    Reads the committed file; generates the mesh with gmsh only if the file is missing
    (the result may then differ from the committed one if the gmsh version differs).
    """
    entry = describe(name)
    if entry.filename is None:
        return entry.build()
    path = DATA_DIR / entry.filename
    if path.is_file():
        return _read_file(path)
    return entry.build()


def resolve(name_or_path: Union[str, os.PathLike]) -> tuple[np.ndarray, np.ndarray, str]:
    """A built-in mesh by name, or a mesh file by path.

    Returns:
        points (n, 3), cells (m, 4) and a label: the catalog name or the path as given.

    Raises:
        ValueError: neither a catalog name nor an existing file (the message lists the
            names); MeshReadError (a ValueError) if the file cannot be read.
    """
    key = os.fspath(name_or_path)
    if key in _BY_NAME:
        return (*load(key), key)
    path = Path(key)
    looks_like_path = (
        path.exists() or path.suffix.lower() in SUFFIXES or os.sep in key or "/" in key
    )
    if not looks_like_path:
        raise ValueError(
            f"unknown mesh {key!r}: not a built-in mesh ({', '.join(names())}) nor a mesh file "
            f"({', '.join(SUFFIXES)})"
        )
    data = read_mesh(path)
    return np.array(data.points), np.array(data.cells), key


def check_counts(entry: CatalogEntry, points: np.ndarray, cells: np.ndarray) -> list[str]:
    """Messages for every expected count the mesh misses (empty if it meets them all)."""
    problems = []
    for what, actual, expected in (
        ("cells", len(cells), entry.expected_cells),
        ("nodes", len(points), entry.expected_nodes),
    ):
        if expected is not None:
            count, tol = expected
            if abs(actual / count - 1.0) > tol:
                problems.append(
                    f"{entry.name}: {actual} {what}, more than {100 * tol:g} % from {count}"
                )
    return problems


def regenerate(which: Optional[Iterable[str]] = None, data_dir: Path = DATA_DIR) -> list[Path]:
    """Generate the file-backed built-in meshes with gmsh and write them to ``data_dir``.

    Raises:
        RuntimeError: if a generated mesh misses its expected counts (nothing is written
            for that mesh).
    """
    selected = [describe(n) for n in (which if which is not None else names())]
    data_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for entry in selected:
        if entry.filename is None:
            continue
        points, cells = entry.build()
        problems = check_counts(entry, points, cells)
        if problems:
            raise RuntimeError("; ".join(problems))
        path = data_dir / entry.filename
        if path.suffix == ".npz":
            np.savez_compressed(path, points=points, cells=cells)
        else:
            write_mesh(path, points, cells)
        written.append(path)
    return written


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m meshes.catalog", description="The built-in meshes."
    )
    parser.add_argument(
        "--regenerate",
        nargs="*",
        metavar="NAME",
        help="rebuild the committed files (all if no name)",
    )
    args = parser.parse_args(argv)
    if args.regenerate is not None:
        for path in regenerate(args.regenerate or None):
            print(f"wrote {path}")
    for name in names():
        points, cells = load(name)
        print(
            f"{name:12s} {len(points):7d} nodes {len(cells):7d} cells  {describe(name).description}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
