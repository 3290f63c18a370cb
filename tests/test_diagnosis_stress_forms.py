"""A Cauchy stress wrong by one tensor form per cell, the initial-stress stiffness following it
and the tangent right (conformance.diagnosis.stress_forms). The engine is MJED's answer (the
oracle's stand-in) with a stress error added by this file's own element loop: St Venant-Kirchhoff's
lam tr E I not pushed forward (delta sigma = lam tr E (I - b) / J), or its mu (b^2 - b) / J
doubled; the nearby mistakes (the tangent wrong too, an error of no listed form) are not named.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split
from diagnosis_stubs import cell_gradients

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.stress_forms import same_state_groups, stress_form_findings
from conformance.judge.compare import DOUBLE

EYE = np.eye(3)


def _state(uniform):
    points, cells = box_mesh(2, jitter=0.0 if uniform else 0.2, seed=4)
    x = points @ np.diag([1.12, 0.94, 0.96]).T
    if not uniform:
        x = x + 0.05 * np.random.default_rng(4).standard_normal(points.shape)
    return points, cells, x


def _with_stress_error(points, cells, x, dsigma, tangent=0.0):
    """(f, K) of MJED plus a Cauchy stress error dsigma(F, J) (m, 3, 3) per cell in the force
    -v dsigma g_a and the initial-stress stiffness v (g_a . dsigma g_b) I; tangent: a further
    material-tangent error tangent * v g_a (x) g_b per cell (a mistake this reading must not
    explain).
    """
    model = default_material("StVenantKirchhoff")
    _, f_o, K_o, _ = mjed_split(model, points, cells, x)
    V0, D, F, J = cell_gradients(points, cells, x)
    g = D @ np.linalg.inv(F)
    v = J * V0
    ds = dsigma(model, F, J)
    fe = -np.einsum("m,mij,maj->mai", v, ds, g)
    Ke = np.einsum("m,mai,mij,mbj,kl->makbl", v, g, ds, g, EYE)
    Ke = Ke + tangent * np.einsum("m,mak,mbl->makbl", v, g, g)
    df, dK = assemble(cells, points.shape[0], fe, Ke.reshape(-1, 12, 12))
    return f_o + df, sp.csr_matrix(K_o) + dK


def _not_pushed(model, F, J):
    E = 0.5 * (F.swapaxes(1, 2) @ F - EYE)
    trE = np.einsum("mii->m", E)
    b = F @ F.swapaxes(1, 2)
    return (model.lam * trE / J)[:, None, None] * (EYE - b)


def _mu_doubled(model, F, J):
    b = F @ F.swapaxes(1, 2)
    return (model.mu / J)[:, None, None] * (b @ b - b)


def _found(uniform, dsigma, tangent=0.0):
    points, cells, x = _state(uniform)
    model = default_material("StVenantKirchhoff")
    split, _, _, s = mjed_split(model, points, cells, x)
    f, K = _with_stress_error(points, cells, x, dsigma, tangent)
    values = {"mu": model.mu, "lam": model.lam}
    return stress_form_findings(split, f, K, s, DOUBLE, values)


def test_lam_tr_e_not_pushed_forward_is_named_on_a_random_state():
    (found,) = _found(False, _not_pushed)
    assert found.code == "stress-form" and "(I - b)" in found.title, found.title
    assert "push-forward" in found.title


def test_mu_term_doubled_is_named_with_its_coefficient():
    (found,) = _found(False, _mu_doubled)
    assert "(b^2 - b)" in found.title and "beta = mu / J in every cell" in found.evidence


@pytest.mark.parametrize("uniform", [False, True])
def test_the_tangent_wrong_too_or_another_form_is_not_named(uniform):
    assert _found(uniform, _mu_doubled, tangent=300.0) == []

    def other(model, F, J):  # a deviatoric error along F^T F: no listed form
        C = F.swapaxes(1, 2) @ F
        return 500.0 * (C - np.einsum("mii->m", C)[:, None, None] / 3.0 * EYE)

    assert _found(uniform, other) == []


def test_a_homogeneous_state_has_one_unknown():
    points, cells, x = _state(True)
    _, _, F, _ = cell_gradients(points, cells, x)
    assert same_state_groups(F @ F.swapaxes(1, 2)).max() == 0
    points, cells, x = _state(False)
    _, _, F, _ = cell_gradients(points, cells, x)
    assert same_state_groups(F @ F.swapaxes(1, 2)).max() == len(cells) - 1
