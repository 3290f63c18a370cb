"""The held-out corpus tests/heldout_mistakes_7/: the seventh corpus (30 mistakes written blind to
the diagnosis, in engines of another architecture: ported Abaqus UMAT-style material routines,
vectorised over the cells, returning the Cauchy stress and DDSDDE, the Jaumann-rate tangent of the
Kirchhoff stress over J, in Abaqus' Voigt order; a driver removes the Jaumann terms to get the
Truesdell spatial tangent and assembles over the current volume with the spatial gradients). Every
correct engine passes and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_7"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
