"""The held-out corpus tests/heldout_mistakes_19/: the nineteenth corpus (29 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the graphics style of "Dynamic
Deformables", Vega FEM and invertible FEM, vectorised over cells with NumPy: the rest edge matrix
Dm, Dm^-1 and V0 = det Dm / 6 per cell, F = Ds Dm^-1, the first Piola-Kirchhoff stress
P = dPsi/dF written in F, the 9 x 12 matrix dF/dx (column-major vec(F)), f_e = -V0 dF/dx^T vec(P)
and K_e = V0 dF/dx^T (dP/dF) dF/dx with dP/dF a 9 x 9 matrix per cell; the invariant laws through
I_C = tr(F^T F), II_C = ||F^T F||_F^2 and J = det F (dJ/dF the cofactor matrix, its Hessian from
the cross-product matrices of F's columns), Ogden through the rotation-variant SVD of F and the
analytic eigensystem of dP/dF (scaling, twist and flip modes), Costa in F with the kit's per-cell
frame; dense, COO or CSR stiffness). Every correct engine passes and no mistaken engine is passed
(tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_19"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=29)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
