"""The held-out corpus tests/heldout_mistakes_9/: the ninth corpus (33 mistakes written blind to
the diagnosis, in engines of another architecture: research-code engines that write the Cauchy
stress in closed form in the current configuration, vectorised over the cells: F = Ds Dm^-1,
b = F F^T, sigma(b, J) per material (St Venant-Kirchhoff and Costa through S and F S F^T / J,
Ogden through b^(alpha/2) by a Denman-Beavers square root), element forces over the deformed cell
f_a = -v sigma grad_x N_a, and the element stiffness by complex-step differentiation of that force
routine, K_e[:, j] = -Im f(x + i h e_j) / h). Every correct engine passes and no mistaken engine
is passed (tests/heldout_support.py).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, check_manifest, check_verdict, corpus_rows, entries

NAME = "heldout_mistakes_9"
pytestmark = MARKS


def test_manifest_lists_every_engine():
    check_manifest(NAME, controls=3, mistakes=33)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    return corpus_rows(NAME, tmp_path_factory)


@pytest.mark.parametrize("entry", entries(NAME), ids=lambda e: e["file"])
def test_verdict(rows, entry):
    check_verdict(rows, entry)
