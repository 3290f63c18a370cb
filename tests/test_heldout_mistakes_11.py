"""The held-out corpus tests/heldout_mistakes_11/: the eleventh corpus (30 mistakes written blind
to the diagnosis, in engines of another architecture: Python ports of the structure of a
SOFA-style hyperelastic tetrahedral force field with edge-based stiffness, vectorised over the
cells with NumPy: rest shape vectors from the inverse rest edge matrix, V0, F, C, J and the
invariants per tetrahedron; a material object with spk(C, J, p) -> S and
apply_elasticity(C, H, p) -> dS (the elasticity tensor applied to a symmetric direction H = dE,
Ogden through the eigen-decomposition of C); nodal forces f_a = -V0 F S dN_a; 3x3 node-pair
blocks stored per mesh edge (an edge table built from the cells, the reversed direction taken
as the transpose) and per vertex, assembled dense, COO or CSR). Every correct engine passes and
no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_11"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
