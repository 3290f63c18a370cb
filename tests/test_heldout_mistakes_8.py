"""The held-out corpus tests/heldout_mistakes_8/: the eighth corpus (30 mistakes written blind to
the diagnosis, in engines of another architecture: invertible-FEM style engines as real-time
simulation and graphics codes write them, vectorised over the cells: F = Ds Dm^-1, a
rotation-variant SVD, the isotropic energies as functions of the singular values,
P = U diag(dPsi/dsigma) V^T and dP/dF by Teran's blocks in the SVD basis (the 3x3 Hessian in the
singular values and the 2x2 blocks from analytic divided differences); Costa through S and CC in
its per-cell fibre frames; Sifakis' forces f = -V0 P Dm^-T). Every correct engine passes and no
mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_8"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
