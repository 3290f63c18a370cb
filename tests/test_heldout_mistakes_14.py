"""The held-out corpus tests/heldout_mistakes_14/: the fourteenth corpus (31 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in principal stretches in the
Simo-Taylor spectral style, vectorised over cells with NumPy: shape-function gradients and rest
volumes from the rest edge matrix, F per cell, the eigen-decomposition of C = F^T F
(numpy.linalg.eigh), the isotropic energies evaluated in the principal stretches through
second-order jets over the invariants computed from the stretches (or over the stretches for Ogden
and St Venant-Kirchhoff), principal stresses S_a = (1/lambda_a) dW/dlambda_a assembled as
S = sum S_a N_a (x) N_a, the material tangent in spectral form (the principal block and the shear
terms (S_a - S_b)/(c_a - c_b) between distinct directions, written without cancellation for
coincident stretches), Costa in closed form in its per-cell fibre frames, A = I (x) S + F F CC and
the element force and stiffness contracted with the shape-function gradients, assembled into a
dense, COO or CSR stiffness). Every correct engine passes and no mistaken engine is passed
(tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_14"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=31)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
