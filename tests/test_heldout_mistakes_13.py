"""The held-out corpus tests/heldout_mistakes_13/: the thirteenth corpus (31 mistakes written blind
to the diagnosis, in engines of another architecture: total-Lagrangian P1 engines in Voigt notation
in the style of Bathe's textbook and of TLED codes (Miller, Joldes et al.), vectorised over cells
with NumPy: rest shape-function derivatives dh/dX (m, 4, 3) and volumes V0 precomputed, F = I + H
from the displacements u = x - X, the second Piola-Kirchhoff stress S as a Voigt 6-vector in the
order (11, 22, 33, 12, 23, 13) (Ogden through the eigen-decomposition of C, Costa through per-cell
6 x 6 Voigt rotations into its fibre frames), the material tangent D = 2 dS/dC as a 6 x 6 matrix
(closed form, spectral, or the complex step of S in the six components of C), the nonlinear
strain-displacement matrix B = B_L0 + B_L1 (6 x 12, engineering shear rows), r = V0 B^T S and
K_e = V0 (B^T D B + K_geo), assembled through the (m, 12) dof map into a dense, COO or CSR
stiffness). Every correct engine passes and no mistaken engine is passed
(tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_13"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=31)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
