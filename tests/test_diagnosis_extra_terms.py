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


def test_an_invariant_typed_for_another_in_a_linear_term_is_named_with_its_coefficient():
    """Mooney-Rivlin's c2 (I2b - 3) written c2 (I1b - 3): the engine is mjed's Mooney-Rivlin
    with c1 + c2 on I1b and no I2b term. Named as I1b typed for I2b with the coefficient c2 (the
    formula names both, so both readings of the pair are said); the coefficient said as the
    simplest fraction of one parameter or of a product of two.
    """
    from conformance.diagnosis.extra_terms import _coefficient_words, extra_terms

    points, cells, x = _state(seed=1)
    mesh = mjed.TetMesh(points, cells)
    right = mjed.materials.MooneyRivlin(c1=1200.0, c2=400.0, k0=30000.0)
    wrong = mjed.materials.MooneyRivlin(c1=1600.0, c2=0.0, k0=30000.0)
    f_o, K_o = mjed.HyperelasticForceField(mesh, right).force_and_stiffness(x)
    f, K = mjed.HyperelasticForceField(mesh, wrong).force_and_stiffness(x)
    s = scales(0.5, 0.0, f_o, K_o)
    params = {"c1": 1200.0, "c2": 400.0, "k0": 30000.0}
    formula = "((c1*(I1b - 3) + c2*(I2b - 3)) + k0/2*ln(J)**2)"
    found = extra_terms(points, cells, x, f, K, f_o, sp.csr_matrix(K_o), s, DOUBLE, params, formula)
    titles = [t for t, *_ in found]
    assert len(found) == 1 and "c2 I2b of the energy written with I1b" in titles[0], titles
    assert "1/3 c1" not in titles[0]  # c2 = c1 / 3 here: the parameter itself is simpler
    assert _coefficient_words(-1050.0, {"c1": 1500.0, "c2": 1.4})[1] == "-1/2 c1 c2"
