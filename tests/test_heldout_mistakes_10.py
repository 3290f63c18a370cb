"""The held-out corpus tests/heldout_mistakes_10/: the tenth corpus (34 mistakes written blind to
the diagnosis, in engines of another architecture: research-code engines that write only the
strain energy of each cell, V0 W(F), and take its derivatives from hyper-dual numbers
a + b e1 + c e2 + d e1 e2 (Fike and Alonso's forward-mode second derivatives) in a small NumPy
class vectorised over the cells (powers, exp, log, 3x3 determinant and inverse by cofactors,
Ogden's eigenvalue power sum through eigh of the real part with a Daleckii-Krein second-order
term): the element force f_e = -dE/dx_e from the e1 parts (12 seeds), the element stiffness
K_e = d2E/dx_e2 from the e1 e2 parts (78 seed pairs, symmetric fill), assembled node-major as
dense, COO or CSR). Every correct engine passes and no mistaken engine is passed
(tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_10"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=34)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
