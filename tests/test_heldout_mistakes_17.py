"""The held-out corpus tests/heldout_mistakes_17/: the seventeenth corpus (31 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the FEBio style, spatial
(updated-Lagrangian) formulation, vectorised over cells with NumPy: shape-function gradients and
rest volumes from the rest edge matrix, F, J, the deformed volume v = J V0, the spatial gradients
g_a = F^-T G_a and b = F F^T per cell; per material the Cauchy stress and the spatial (Truesdell)
elasticity tensor as full 3x3x3x3 arrays, FEBio's uncoupled split (deviatoric projection of the
fictitious stress and tangent, p and p + J dp/dJ) for the decoupled laws, Ogden in spectral form,
Costa with its fibre frame pushed forward; f_a = -v sigma g_a and K_ab = v [g_a . c . g_b +
(g_a . sigma . g_b) I], assembled into a dense, COO or CSR stiffness). Every correct engine passes
and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_17"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=31)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
