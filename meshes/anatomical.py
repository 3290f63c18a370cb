"""An anatomical-style copy of the generated liver, as organ meshes come from other tools.

SOFA's example livers and meshes segmented from CT come in gmsh's legacy format 1.0
($NOD/$ELM), in centimetre-like units, with the y axis up, boundary triangles beside the
tetrahedra, and node numbers that follow the mesher's order. This module writes such a file
from a catalog mesh (metres, z up) so that the whole path (reader, units, numbering, gravity
direction, a liver hung from three nodes) can be exercised and demonstrated without a patient
mesh:

    python -m meshes.anatomical organ.msh ids.txt     # then:
    mjed-verify liver --mesh organ.msh --units cm --gravity 0,-9.81,0 --fixed nodes:ids.txt

Conversion: (x, y, z) in metres, z up -> (x, z, -y) * 100 in centimetres, y up (a rotation:
cell orientation is kept). Nodes are written in a shuffled order and numbered 1..n in that
order, so the file's numbering differs from the catalog's. ``ids.txt`` lists, in the file's
numbering, three nodes to hang the organ from: the highest node of the right lobe, the highest
of the left lobe and the highest posterior node between them (where the vena cava is).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Sequence, Tuple

import numpy as np

__all__ = ["anatomical_liver", "write_anatomical_liver", "hanging_nodes"]


def anatomical_liver(source: str = "liver-coarse", *, seed: int = 0):
    """(points (n, 3) in cm y up, cells (m, 4), boundary triangles (k, 3), file order (n,)).

    ``order[i]`` is the catalog node written i-th (so it gets the number i + 1); points and
    cells are in file order already.
    """
    import meshes
    from meshes.tetra import boundary_triangles

    points, cells = meshes.load(source)
    rotated = 100.0 * np.column_stack([points[:, 0], points[:, 2], -points[:, 1]])
    order = np.random.default_rng(seed).permutation(len(points))
    position = np.empty_like(order)
    position[order] = np.arange(len(order))
    file_cells = position[cells]
    return rotated[order], file_cells, boundary_triangles(file_cells), order


def hanging_nodes(points: np.ndarray) -> np.ndarray:
    """Three node positions (0-based) to hang a y-up liver from (see the module docstring)."""
    x, y, z = points.T
    lo, mid_lo, mid_hi, hi = np.quantile(x, [0.3, 0.4, 0.6, 0.7])
    right = np.flatnonzero(x >= hi)
    left = np.flatnonzero(x <= lo)
    middle = np.flatnonzero((x >= mid_lo) & (x <= mid_hi))
    chosen = [
        right[np.argmax(y[right])],
        left[np.argmax(y[left])],
        middle[np.argmax(y[middle] - z[middle])],
    ]
    return np.array(chosen, dtype=np.int64)


def write_anatomical_liver(
    msh_path, ids_path, source: str = "liver-coarse", *, seed: int = 0
) -> Tuple[Path, np.ndarray]:
    """Write the legacy gmsh file and the ids file; returns (msh path, the three node numbers)."""
    from meshes.formats.gmsh_ascii import write_gmsh_legacy

    points, cells, triangles, _ = anatomical_liver(source, seed=seed)
    path = write_gmsh_legacy(msh_path, points, cells, triangles=triangles)
    numbers = hanging_nodes(points) + 1  # the file numbers nodes 1..n in the order written
    Path(ids_path).write_text(
        "# nodes the liver hangs from, numbered as in "
        + Path(msh_path).name
        + " (gmsh node numbers)\n"
        + "\n".join(map(str, numbers.tolist()))
        + "\n"
    )
    return path, numbers


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m meshes.anatomical", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("msh", help="the legacy gmsh file to write")
    parser.add_argument("ids", help="the file of the three node numbers to write")
    parser.add_argument(
        "--source", default="liver-coarse", help="catalog mesh to convert (default liver-coarse)"
    )
    args = parser.parse_args(argv)
    path, numbers = write_anatomical_liver(args.msh, args.ids, args.source)
    print(
        f"wrote {path} (legacy gmsh 1.0, cm, y up) and {args.ids} (node numbers {numbers.tolist()})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
