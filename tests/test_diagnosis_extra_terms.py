"""One energy term more or less than the oracle's (conformance.diagnosis.extra_terms); MJED
stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from conformance.diagnosis.extra_terms import _material, library
from conformance.judge.compare import DOUBLE, scales

MU, LAM = 3000.0, 9000.0


def _state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    return points, cells, x


def _with(model, points, cells, x, extra):
    """The mjed force and stiffness of ``model`` plus ``extra`` times the library term I2."""
    mesh = mjed.TetMesh(points, cells)
    f, K = mjed.HyperelasticForceField(mesh, model).force_and_stiffness(x)
    groups = dict(library())["I2"]
    f_t, K_t = mjed.HyperelasticForceField(mesh, _material(groups)).force_and_stiffness(x)
    return f + extra * f_t, sp.csr_matrix(K + extra * K_t), f, sp.csr_matrix(K)


def test_an_i2_coefficient_off_by_a_quarter_of_mu_is_named():
    """St Venant-Kirchhoff's mu tr(E^2) expanded with tr(C^2) = I1^2 - I2: mu/4 I2 over."""
    from conformance.diagnosis.extra_terms import extra_terms

    points, cells, x = _state()
    model = mjed.materials.StVenantKirchhoff(mu=MU, lam=LAM)
    f, K, f_o, K_o = _with(model, points, cells, x, MU / 4.0)
    s = scales(0.5, 0.0, f_o, K_o)
    found = extra_terms(points, cells, x, f, K, f_o, K_o, s, DOUBLE, {"mu": MU, "lam": LAM})
    assert [t for t, *_ in found] and "1/4 mu I2" in found[0][0], [t for t, *_ in found]
    # nearby: a coefficient that is no simple multiple of a parameter, and the right engine
    f, K, *_ = _with(model, points, cells, x, 0.3137 * MU)
    assert extra_terms(points, cells, x, f, K, f_o, K_o, s, DOUBLE, {"mu": MU, "lam": LAM}) == []
    assert extra_terms(points, cells, x, f_o, K_o, f_o, K_o, s, DOUBLE, {"mu": MU}) == []
