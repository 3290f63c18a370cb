"""Element matrices made positive semi-definite before assembly (conformance.diagnosis.
definiteness): a St Venant-Kirchhoff engine, compressed so that many cells' Hessians are
indefinite, whose 12 x 12 element matrices are projected here (negative eigenvalues clamped to
zero, or made positive) before assembly; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from conformance.diagnosis.definiteness import definiteness_findings
from conformance.diagnosis.elements import assemble
from conformance.judge.compare import DOUBLE
from mjed import materials as M


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(3, jitter=0.2, seed=7)
    rng = np.random.default_rng(7)
    x = points @ np.diag([0.7, 1.1, 1.05]).T + 0.05 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(M.StVenantKirchhoff(mu=1e3, lam=4e3), points, cells, x)
    return split, f_o, K_o, s


def _projected(Ke, change):
    """The engine's element matrices: each one's eigenvalues passed through ``change``."""
    out = np.empty_like(Ke)
    for e, k in enumerate(Ke):  # the engine's own loop over its cells
        w, V = np.linalg.eigh(k)
        out[e] = (V * change(w)) @ V.T
    return out


@pytest.mark.parametrize(
    "change, named",
    [(lambda w: np.maximum(w, 0.0), "clamped"), (np.abs, "absolute")],
)
def test_projected_element_matrices_are_named(case, change, named):
    split, f_o, K_o, s = case
    K = assemble(split.cells, split.n, split.fe, _projected(split.Ke, change))[1]
    found = definiteness_findings(split, f_o, K, s, DOUBLE)
    assert [f.figures.get("projection") for f in found] == [named], found
    assert found[0].figures["indefinite_cells"] > 0


def test_another_stiffness_error_is_not_a_projection(case):
    split, f_o, K_o, s = case
    assert definiteness_findings(split, f_o, 1.001 * K_o, s, DOUBLE) == []
    # the projection's stiffness but a wrong force: not this mistake alone
    K = assemble(split.cells, split.n, split.fe, _projected(split.Ke, np.abs))[1]
    assert definiteness_findings(split, 1.01 * f_o, K, s, DOUBLE) == []
