"""The held-out corpus tests/heldout_mistakes_15b/: a second fifteenth corpus (27 mistakes written
blind to the diagnosis, in engines of the MJED architecture, the paper's method: P1 engines
vectorised over cells with NumPy, rest shape vectors D_a and volumes V0 from the rest edge matrix,
per material a table of terms f_k(J) g_k(C) and groups c phi(u) as mjed's decomposition() declares
them, each evaluated by the engine's own f, f', f'', g, dg/dC and its derivative; dJ_a = J F^-T D_a,
the antisymmetric d2J_ab, dg_a = 2 F G D_a, and the node-pair blocks from the product rule,
assembled into a dense, COO or CSR stiffness). It was written in parallel with, and independently
of, tests/heldout_mistakes_15/ (another session's corpus of the same architecture). Every correct
engine passes and no mistaken engine is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_15b"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=27)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
