"""The held-out corpus tests/heldout_mistakes_20/: the twentieth corpus (30 mistakes written blind
to the diagnosis, in engines of another architecture: P1 engines in the style of a commercial
code's hyperelastic user material, vectorised over cells with NumPy, in two layers: a user routine
per material returns the energy density and its derivatives packed as arrays (UHYPER manner,
UI1 = (dU/dI1b, dU/dI2b, dU/dJ) and UI2 = (d2U/dI1b2, d2U/dI2b2, d2U/dJ2, d2U/dI1b dI2b,
d2U/dI1b dJ, d2U/dI2b dJ); Costa in the UANISOHYPER_STRAIN manner, DUDE and the packed 21-entry
D2UDE2 in the cell's fibre frame with engineering shears; Ogden as a principal-stretch routine in
the deviatoric stretches), and a generic driver per routine type forms the second Piola-Kirchhoff
stress S = 2 dU/dC and the material tangent C_mat = 4 d2U/dC2 (isochoric projections and d2I/dC2
terms, the fibre-frame rotation, or the spectral assembly) and assembles f_e = -V0 B^T S,
K_e = V0 B^T C_mat B + V0 (G_a . S . G_b) I with the material B matrix (6 x 12, Voigt 11, 22, 33,
23, 13, 12, engineering shear rows), into a dense, COO or CSR stiffness). Every correct engine
passes and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_20"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=30)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
