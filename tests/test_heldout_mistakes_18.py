"""The held-out corpus tests/heldout_mistakes_18/: the eighteenth corpus (29 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the Abaqus UMAT style,
vectorised over cells with NumPy: F = Ds Dm^-1, J, b = F F^T, the deformed volume v = J V0 and the
spatial gradients g_a = F^-T G_a per cell; a UMAT-like routine per material returns the Cauchy
stress in Voigt form (Abaqus order 11, 22, 33, 12, 13, 23) and DDSDDE (the Jaumann-rate tangent of
the Kirchhoff stress over J, engineering shear strains); the element converts DDSDDE to the
Truesdell tangent by subtracting the rate terms 1/2 (d_ik s_jl + d_il s_jk + s_ik d_jl + s_il d_jk)
and assembles K_e = v B^T D B + v (g_a . sigma . g_b) I, f_e = -v B^T sigma with the spatial
B matrix (6 x 12, engineering shear rows), into a dense, COO or CSR stiffness). Every correct
engine passes and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_18"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=29)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
