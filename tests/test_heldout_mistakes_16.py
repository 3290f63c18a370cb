"""The held-out corpus tests/heldout_mistakes_16/: the sixteenth corpus (29 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the mixed / hybrid style of
commercial and research codes (Simo-Taylor-Pister three-field u-p-theta, C3D4H-like hybrid tets,
F-bar), vectorised over cells with NumPy: shape-function gradients and rest volumes from the rest
edge matrix, F, J and the isochoric F_bar = J^(-1/3) F per cell, the isochoric energy through
second-order jets over (I1, I2, J) giving the deviatoric stress and its tangent, one dilatation
theta and one pressure p = U'(theta) per cell statically condensed (theta = J, U'' in the condensed
tangent), A = I (x) S + F F CC and the element force and stiffness contracted with the
shape-function gradients, assembled into a dense, COO or CSR stiffness). Every correct engine passes
and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_16"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=29)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
