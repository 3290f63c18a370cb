"""The held-out corpus tests/heldout_mistakes_15/: the fifteenth corpus (31 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the MJED form of Marchesseau
et al. (MICCAI 2010), vectorised over cells with NumPy: shape vectors and rest volumes precomputed
per tetrahedron, each material declared as a table of MJED terms W = sum_k f_k(J) g_k(C) (f, f',
f''; g, S = 2 dg/dC and dS/dC : H as the paper's beta A H A and beta (H : A) A pieces, or a
Hadamard piece in a basis for Ogden's eigenvalues and Costa's per-cell fibre frame), non-separable
energies (Gent's logarithm, the exponentials of Veronda-Westmann, Demiray and Costa) as an outer
function of such a sum, forces from the paper's per-term formula and the stiffness assembled by
node pairs (4 vertex and 6 edge blocks per cell, each edge block mirrored) into a dense, COO or CSR
stiffness). Every correct engine passes and no mistaken engine is passed
(tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_15"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=31)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
