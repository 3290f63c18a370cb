"""gmsh-based generators of linear tetrahedral meshes.

Every generator returns ``(points, cells)``: points (n, 3) float64, cells (m, 4) int64,
0-based contiguous node numbers, no unreferenced node, every cell positively oriented
(det[x1 - x0, x2 - x0, x3 - x0] / 6 > 0).

The unstructured generators take a target cell count rather than a mesh size: they search
for the gmsh mesh size that lands within ``CELL_COUNT_TOLERANCE`` of it. The search is a
fixed sequence of single-threaded gmsh runs, so the same arguments give the same mesh (on
the same gmsh version).
"""

from __future__ import annotations

import math
import warnings
from typing import Callable, Optional

import numpy as np

from meshes import _gmsh
from meshes.tetra import orient_positively

__all__ = ["unit_cube", "cylinder", "single_tetrahedron", "CELL_COUNT_TOLERANCE"]

#: Relative distance to the target cell count that the generators guarantee (else warn).
CELL_COUNT_TOLERANCE = 0.05

# The search stops early once this close; tighter than the guarantee so that quantities
# tied to the cell count (node count, say) are not pushed to the edge of their own bounds.
_STOP_TOLERANCE = 0.005
_MAX_RUNS = 12

# Cells per h^-3 per unit volume of a gmsh Delaunay mesh with uniform size h (measured on
# the unit cube: about 4.7). Only the starting guess depends on it.
_CELLS_PER_SIZE_CUBED = 4.7

Mesh = tuple[np.ndarray, np.ndarray]


def _check_target(target_cells: int) -> int:
    if isinstance(target_cells, bool) or int(target_cells) != target_cells or target_cells < 1:
        raise ValueError(f"target_cells must be a positive integer, got {target_cells!r}")
    return int(target_cells)


def _mesh_with_size(add_geometry: Callable[[object], None], size: float, seed: int) -> Mesh:
    """One gmsh run: build the geometry, mesh it with uniform size ``size``."""
    options = {"Mesh.MeshSizeMin": size, "Mesh.MeshSizeMax": size, "Mesh.RandomSeed": seed}
    with _gmsh.session(options) as gmsh:
        add_geometry(gmsh)
        gmsh.model.mesh.generate(3)
        return _gmsh.tetrahedra(gmsh)


def _calibrated(
    add_geometry: Callable[[object], None], volume: float, target: int, seed: int
) -> Mesh:
    """Search the mesh size whose mesh has about ``target`` cells and return that mesh.

    The cell count falls roughly like size^-3 but in steps, so the update
    size *= (count / target)^(1/3) is kept inside the bracket of sizes already known to
    give too many and too few cells (bisecting geometrically when it leaves it).
    """
    size = (_CELLS_PER_SIZE_CUBED * volume / target) ** (1.0 / 3.0)
    too_fine, too_coarse = 0.0, math.inf  # sizes known to give too many / too few cells
    best: Optional[Mesh] = None
    best_error = math.inf
    tried: set[float] = set()
    for _ in range(_MAX_RUNS):
        mesh = _mesh_with_size(add_geometry, size, seed)
        tried.add(size)
        count = len(mesh[1])
        error = abs(count / target - 1.0)
        if error < best_error:
            best, best_error = mesh, error
        if error <= _STOP_TOLERANCE:
            break
        if count > target:
            too_fine = max(too_fine, size)
        else:
            too_coarse = min(too_coarse, size)
        proposal = size * (count / target) ** (1.0 / 3.0)
        if not too_fine < proposal < too_coarse and math.isfinite(too_coarse) and too_fine > 0:
            proposal = math.sqrt(too_fine * too_coarse)
        if proposal in tried:
            break
        size = proposal
    assert best is not None
    if best_error > CELL_COUNT_TOLERANCE:
        warnings.warn(
            f"mesh has {len(best[1])} cells, {100 * best_error:.1f} % away from the target "
            f"{target}; gmsh cannot get closer for this geometry",
            RuntimeWarning,
            stacklevel=3,
        )
    return best


def unit_cube(target_cells: int, *, seed: int = 0) -> Mesh:
    """Unstructured Delaunay tetrahedral mesh of the unit cube [0, 1]^3.

    Args:
        target_cells: wanted number of tetrahedra; the result is within 5 % of it
            (a RuntimeWarning says otherwise, which only happens for tiny targets).
        seed: gmsh's ``Mesh.RandomSeed``; other seeds give other meshes of the same size.

    Returns:
        points: (n, 3) float64; cells: (m, 4) int64, positively oriented.
    """
    target = _check_target(target_cells)

    def add_geometry(gmsh) -> None:
        gmsh.model.occ.addBox(0.0, 0.0, 0.0, 1.0, 1.0, 1.0)
        gmsh.model.occ.synchronize()

    return _calibrated(add_geometry, 1.0, target, int(seed))


def cylinder(radius: float, height: float, target_cells: int, *, seed: int = 0) -> Mesh:
    """Unstructured Delaunay tetrahedral mesh of a circular cylinder.

    The axis is the z axis, the base disc lies in z = 0 and the top disc in z = height.
    The curved face is polygonal, so the mesh volume is slightly below pi r^2 h.

    Args:
        radius: cylinder radius (> 0).
        height: cylinder height (> 0).
        target_cells: wanted number of tetrahedra, met within 5 % as for ``unit_cube``.
        seed: gmsh's ``Mesh.RandomSeed``.

    Returns:
        points: (n, 3) float64; cells: (m, 4) int64, positively oriented.
    """
    radius, height = float(radius), float(height)
    if not (radius > 0 and height > 0 and math.isfinite(radius) and math.isfinite(height)):
        raise ValueError(f"radius and height must be positive and finite, got {radius}, {height}")
    target = _check_target(target_cells)

    def add_geometry(gmsh) -> None:
        gmsh.model.occ.addCylinder(0.0, 0.0, 0.0, 0.0, 0.0, height, radius)
        gmsh.model.occ.synchronize()

    return _calibrated(add_geometry, math.pi * radius**2 * height, target, int(seed))


def single_tetrahedron(points: Optional[np.ndarray] = None) -> Mesh:
    """A mesh of one tetrahedron.

    Args:
        points: (4, 3) vertices; default the reference tetrahedron
            (0,0,0), (1,0,0), (0,1,0), (0,0,1).

    Returns:
        points: (4, 3) float64, the vertices as given; cells: (1, 4) int64, which is
        [[0, 1, 2, 3]], or [[0, 2, 1, 3]] if the given vertices are negatively oriented.

    Raises:
        ValueError: if the points do not have shape (4, 3) or span no volume.
    """
    if points is None:
        pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    else:
        pts = np.array(points, dtype=np.float64)
        if pts.shape != (4, 3) or not np.isfinite(pts).all():
            raise ValueError(f"a tetrahedron needs 4 finite points in 3-D, got shape {pts.shape}")
    cells, _ = orient_positively(pts, np.array([[0, 1, 2, 3]], dtype=np.int64))
    return pts, cells
