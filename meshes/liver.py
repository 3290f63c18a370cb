"""A liver-shaped organ meshed with gmsh: a thick right lobe and a thin left lobe.

No patient liver is redistributable here (the paper's mesh came from a CT scan, 3D-IRCADb is
non-commercial), so the shape is built from two ellipsoids fused with OpenCASCADE:

* right lobe: semi-axes 9 x 8 x 7.5 cm, centred at x = +4 cm;
* left lobe: a flat ellipsoid 9 x 6 x 3 cm, centred at x = -7 cm and 2 cm higher, tilted 12
  degrees about the antero-posterior axis (it thins towards the patient's left);
* the fused body is cut by the plane z = -5.5 cm (the flatter visceral underside).

Axes (metres): x from the patient's left (-) to right (+), y from anterior (-) to posterior
(+), z upwards (gravity is -z). The result is about 29 x 16 x 13 cm and 2.6 litres: a large
adult liver (1.5 to 2.5 litres is typical); the scale only sets the gravity load per stiffness.
``liver(5000)`` gives about the paper's mesh (1,240 vertices and
5,000 tetrahedra); the catalog keeps that one and a coarse one for CI.
"""

from __future__ import annotations

import math

from meshes.generate import _calibrated, _check_target

__all__ = ["liver", "LIVER_BOUNDS_APPROX"]

#: approximate bounding box (min, max) of the generated shape, metres.
LIVER_BOUNDS_APPROX = ((-0.155, -0.08, -0.055), (0.13, 0.08, 0.075))


def _add_liver(gmsh) -> None:
    occ = gmsh.model.occ
    right = occ.addSphere(0.0, 0.0, 0.0, 1.0)
    occ.dilate([(3, right)], 0.0, 0.0, 0.0, 0.09, 0.08, 0.075)
    occ.translate([(3, right)], 0.04, 0.0, 0.0)
    left = occ.addSphere(0.0, 0.0, 0.0, 1.0)
    occ.dilate([(3, left)], 0.0, 0.0, 0.0, 0.09, 0.06, 0.03)
    occ.rotate([(3, left)], 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, math.radians(12.0))
    occ.translate([(3, left)], -0.07, -0.005, 0.02)
    body, _ = occ.fuse([(3, right)], [(3, left)])
    cutter = occ.addBox(-0.3, -0.3, -0.3, 0.6, 0.6, 0.3 - 0.055)
    occ.cut(body, [(3, cutter)])
    occ.synchronize()


def liver(target_cells: int = 5000, *, seed: int = 0):
    """Delaunay tetrahedral mesh of the liver-shaped organ.

    Args:
        target_cells: wanted number of tetrahedra (met within 5 %, as for meshes.unit_cube).
        seed: gmsh's Mesh.RandomSeed.

    Returns:
        points (n, 3) float64 in metres; cells (m, 4) int64, positively oriented.
    """
    return _calibrated(_add_liver, 2.6e-3, _check_target(target_cells), int(seed))
