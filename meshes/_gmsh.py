"""A quiet, reproducible gmsh session and the extraction of its linear tetrahedra.

gmsh keeps global state (options, models). ``session`` therefore leaves things as it found
them: it initialises and finalises gmsh only if nobody else had, and otherwise works in a
model of its own and restores every option it changed.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
from typing import Iterator, Mapping

import numpy as np

from meshes.tetra import orient_positively, remove_unreferenced

__all__ = ["session", "tetrahedra", "import_gmsh", "BASE_OPTIONS"]

# gmsh element type of the 4-node (linear) tetrahedron.
_TET4 = 4

# Options every generator sets, so a user's gmshrc or another caller's settings cannot
# change the mesh. Single thread and a fixed seed make the Delaunay mesher deterministic.
BASE_OPTIONS: dict[str, float] = {
    "General.Terminal": 0,
    "General.Verbosity": 0,
    "General.NumThreads": 1,
    "Mesh.MaxNumThreads1D": 1,
    "Mesh.MaxNumThreads2D": 1,
    "Mesh.MaxNumThreads3D": 1,
    "Mesh.Algorithm": 6,  # 2-D Frontal-Delaunay on the faces
    "Mesh.Algorithm3D": 1,  # 3-D Delaunay
    "Mesh.ElementOrder": 1,
    "Mesh.RecombineAll": 0,
    "Mesh.SubdivisionAlgorithm": 0,
    "Mesh.Optimize": 1,
    "Mesh.OptimizeNetgen": 0,
    "Mesh.Smoothing": 1,
    "Mesh.MeshSizeFactor": 1.0,
    "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeFromPoints": 0,
    # With the boundary sizes extended inwards, the whole volume follows the integer number
    # of segments per edge and the cell count jumps by ~20 % between neighbouring sizes.
    # Without it the interior follows the requested size smoothly, which lets the
    # calibration hit a target count.
    "Mesh.MeshSizeExtendFromBoundary": 0,
}

_model_counter = itertools.count()


def import_gmsh():
    """Import the gmsh module, with an error that says how to get it."""
    try:
        import gmsh  # noqa: PLC0415 - optional dependency, imported on first use
    except ImportError as exc:  # pragma: no cover - depends on the machine
        raise ImportError(
            "mesh generation needs the gmsh Python module (Debian: python3-gmsh, or pip install "
            "gmsh); the committed meshes in meshes/data load without it"
        ) from exc
    return gmsh


@contextlib.contextmanager
def _stderr_silenced() -> Iterator[None]:
    """Silence file descriptor 2, where gmsh's C++ core prints, for the duration."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, AttributeError, ValueError):  # no real fd 2: nothing to silence
        yield
        return
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _is_initialized(gmsh) -> bool:
    if hasattr(gmsh, "isInitialized"):  # gmsh >= 4.9
        return bool(gmsh.isInitialized())
    # gmsh 4.8 has no isInitialized. Before the first initialize, model.list() is empty
    # (an initialised session always has its default model); after a finalize it raises
    # and prints "Gmsh has not been initialized", which we keep off the terminal.
    with _stderr_silenced():
        try:
            return len(gmsh.model.list()) > 0
        except Exception:  # noqa: BLE001 - gmsh raises bare Exception
            return False


@contextlib.contextmanager
def session(options: Mapping[str, float]) -> Iterator[object]:
    """A gmsh session with ``BASE_OPTIONS`` plus ``options`` set, in a fresh current model.

    Yields:
        the ``gmsh`` module.
    """
    gmsh = import_gmsh()
    owner = not _is_initialized(gmsh)
    if owner:
        # readConfigFiles=False: a user's gmshrc must not change our meshes.
        gmsh.initialize(readConfigFiles=False)
        gmsh.option.setNumber("General.Terminal", 0)
    settings = {**BASE_OPTIONS, **options}
    saved: dict[str, float] = {}
    previous_model = None
    model = f"meshes-{os.getpid()}-{next(_model_counter)}"
    try:
        if not owner:
            saved = {name: gmsh.option.getNumber(name) for name in settings}
            previous_model = gmsh.model.getCurrent()
        for name, value in settings.items():
            gmsh.option.setNumber(name, float(value))
        gmsh.model.add(model)
        yield gmsh
    finally:
        if owner:
            gmsh.finalize()
        else:
            with contextlib.suppress(Exception):
                gmsh.model.setCurrent(model)
                gmsh.model.remove()
            with contextlib.suppress(Exception):
                if previous_model is not None:
                    gmsh.model.setCurrent(previous_model)
            for name, value in saved.items():
                gmsh.option.setNumber(name, value)


def tetrahedra(gmsh) -> tuple[np.ndarray, np.ndarray]:
    """The linear tetrahedra of the current gmsh model, compacted and positively oriented.

    Returns:
        points: (n, 3) float64, only the nodes some tetrahedron uses, ordered by gmsh tag.
        cells: (m, 4) int64, 0-based, every signed volume > 0.
    """
    _, elem_nodes = gmsh.model.mesh.getElementsByType(_TET4)
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    if len(elem_nodes) == 0:
        raise RuntimeError("gmsh produced no tetrahedra")
    node_tags = np.asarray(node_tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    # gmsh tags are 1-based and may have gaps; map them to row numbers of the sorted tags.
    order = np.argsort(node_tags, kind="stable")
    rows = np.searchsorted(node_tags[order], np.asarray(elem_nodes, dtype=np.int64))
    points, cells, _ = remove_unreferenced(coords[order], rows.reshape(-1, 4))
    cells, _ = orient_positively(points, cells)
    return points, cells
