"""The held-out corpus tests/heldout_mistakes_6/: the sixth corpus (30 mistakes written blind to
the diagnosis, in engines of another architecture: total-Lagrangian after Holzapfel's textbook,
the second Piola stress and the material elasticity tensor per cell in the decoupled
volumetric/isochoric form with the projection tensors, the first Piola stress P = F S and the
first elasticity tensor A = delta S + F F CC, no Voigt matrices). Every correct engine passes and
no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_6"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
