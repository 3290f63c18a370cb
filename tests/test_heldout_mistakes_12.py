"""The held-out corpus tests/heldout_mistakes_12/: the twelfth corpus (30 mistakes written blind
to the diagnosis, in engines of another architecture: FElupe / scikit-fem style P1 engines whose
arrays keep the tensor components first and the quadrature point and cell axes last (dhdX
(4, 3, q, m), F and P (3, 3, q, m), the first elasticity tensor A = dP/dF (3, 3, 3, 3, q, m)),
every contraction an np.einsum over the trailing axes, one quadrature point weighted by the
cell's rest volume det(dX/dr)/6; the material a function of F returning P (from its invariants,
Costa with its per-cell frames, Ogden through the Denman-Beavers square root of C) and A (closed
form for St Venant-Kirchhoff and Neo-Hookean, otherwise the complex step of P in F); element
force r_a = P . dhdX_a dV and element matrix K_ab = dhdX_a . A . dhdX_b dV, assembled through
the (cells x 12) dof map into a dense, COO or CSR stiffness). Every correct engine passes and no
mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_12"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
