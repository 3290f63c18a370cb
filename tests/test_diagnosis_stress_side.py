"""A stress written wrongly by hand, the tangent derived separately
(conformance.diagnosis.stress_side).

The engines are written here in the Lagrangian form a UMAT or total-Lagrangian code uses: the
second Piola stress S and the material tangent CC = 2 dS/dC as two formulas of C, the force
f_a = -V0 F S D_a and the stiffness V0 [(D_a . S D_b) Id + F (CC : D_a D_b) F^T] (not with the
module's MJED blocks); MJED stands in for the oracle. Each mistake comes with a nearby one that
must not get the cause: the same factor in the stress and the tangent together (another
energy), the wrong gradient in the stress only.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.stress_side import stress_side_findings
from conformance.judge.compare import DOUBLE

EYE = np.eye(3)


def _case(name, seed=0):
    model = default_material(name)
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag((1.1, 0.95, 0.92)).T + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, split, f_o, K_o, s


def _odot(A):
    """(A (.) A)_IJKL = 1/2 (A_IK A_JL + A_IL A_JK), (m, 3, 3, 3, 3)."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, A) + np.einsum("mil,mjk->mijkl", A, A))


def _dyad(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def _engine(split, S, CC):
    """The force and stiffness a total-Lagrangian engine assembles from S (m, 3, 3) and
    CC (m, 3, 3, 3, 3).
    """
    F, D, V0 = split.F, split.D, split.V0
    m = F.shape[0]
    fe = -np.einsum("m,mik,mkl,mal->mai", V0, F, S, D)
    geo = np.einsum("maj,mjl,mbl,ik->maibk", D, S, D, EYE)
    mat = np.einsum("miI,maJ,mIJKL,mkK,mbL->maibk", F, D, CC, F, D)
    Ke = V0[:, None, None, None, None] * (geo + mat)
    return assemble(split.cells, split.n, fe, Ke.reshape(m, 12, 12))


def _neo(split, model, stress_mu=1.0, tangent_mu=1.0):
    """Neo-Hookean S and CC with mu scaled by stress_mu in S, by tangent_mu in CC."""
    C = np.einsum("mki,mkj->mij", split.F, split.F)
    Ci = np.linalg.inv(C)
    L = 0.5 * np.log(np.linalg.det(C))
    mu, lam = model.mu, model.lam
    S = stress_mu * mu * (EYE - Ci) + lam * L[:, None, None] * Ci
    w = 2.0 * (tangent_mu * mu - lam * L)
    CC = lam * _dyad(Ci, Ci) + w[:, None, None, None, None] * _odot(Ci)
    return _engine(split, S, CC)


def _find(model, points, cells, x, f, K, f_o, K_o, s):
    return stress_side_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE, True)


def test_neo_hookean_mu_halved_in_the_stress_only_is_named_with_mu():
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=3)
    f, K = _neo(split, model)
    assert np.allclose(f, f_o, rtol=0, atol=1e-10 * np.abs(f_o).max())  # the engine is right
    assert _find(model, points, cells, x, f, K, f_o, K_o, s) == []
    f, K = _neo(split, model, stress_mu=0.5)
    found = _find(model, points, cells, x, f, K, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "stress-coefficient"
    assert "mu/2 where mu belongs in the stress" in found[0].title
    assert "material tangent and the energy right" in found[0].title
    # nearby: mu halved in the stress and the tangent (another energy's): not this cause
    f, K = _neo(split, model, stress_mu=0.5, tangent_mu=0.5)
    assert _find(model, points, cells, x, f, K, f_o, K_o, s) == []


def _demiray(split, model, k=1.0, rank_one=True, hessian=False):
    """Demiray's S and CC, W = c exp(Y) + k0/2 (ln J)^2 with Y = b J^(-2/3) I1: the derivative
    of J^(-2/3) in dY/dC (kappa J^(-2/3) C^-1, kappa = -1/3) written k kappa, in S and (where
    rank_one) in the dY (x) dY term of CC; with hessian, kappa's linear terms of d2Y/dC2 too.
    """
    C = np.einsum("mki,mkj->mij", split.F, split.F)
    Ci = np.linalg.inv(C)
    J = np.sqrt(np.linalg.det(C))
    I1 = np.einsum("mii->m", C)
    a, b, k0 = model.a, model.b, model.k0
    c = a / (2.0 * b) * np.exp(-3.0 * b)
    q = b * J ** (-2.0 / 3.0)
    kap = -1.0 / 3.0
    col, col4 = (lambda v: v[:, None, None]), (lambda v: v[:, None, None, None, None])
    G = col(q) * (EYE + col(kap * I1) * Ci)
    Gk = col(q) * (EYE + col(k * kap * I1) * Ci)
    e = np.exp(b * J ** (-2.0 / 3.0) * I1)
    one = np.broadcast_to(EYE, Ci.shape)
    h = k if hessian else 1.0
    d2 = h * kap * (_dyad(one, Ci) + _dyad(Ci, one)) - col4(h * kap * I1) * _odot(Ci)
    d2 = col4(q) * (d2 + col4(kap**2 * I1) * _dyad(Ci, Ci))
    GG = _dyad(Gk, Gk) if rank_one else _dyad(G, G)
    L = np.log(J)
    S = col(2.0 * c * e) * Gk + k0 * col(L) * Ci
    CC = col4(4.0 * c * e) * (GG + d2) + k0 * _dyad(Ci, Ci) - 2.0 * k0 * col4(L) * _odot(Ci)
    return _engine(split, S, CC)


def test_demiray_j_part_of_the_gradient_halved_in_the_stress_and_rank_one_is_named():
    model, points, cells, x, split, f_o, K_o, s = _case("Demiray", seed=5)
    f, K = _demiray(split, model)
    assert np.allclose(f, f_o, rtol=0, atol=1e-10 * np.abs(f_o).max())  # the engine is right
    assert abs(K - K_o).max() <= 1e-10 * abs(K_o).max()
    f, K = _demiray(split, model, k=0.5)
    found = _find(model, points, cells, x, f, K, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "stress-gradient" and not found[0].figures["hessian"]
    assert "written -1/6 J^(-2/3) g C^-1 where -1/3 J^(-2/3) g C^-1 belongs" in found[0].title
    assert "the second derivative d2u/dC2 right" in found[0].title
    assert abs(found[0].figures["k"] - 0.5) < 1e-6
    # nearby: the wrong gradient in the stress only, the rank-one term from the right one
    f, K = _demiray(split, model, k=0.5, rank_one=False)
    assert _find(model, points, cells, x, f, K, f_o, K_o, s) == []


def test_demiray_j_part_sign_lost_in_the_gradient_and_the_hessian_is_named():
    model, points, cells, x, split, f_o, K_o, s = _case("Demiray", seed=7)
    f, K = _demiray(split, model, k=-1.0, hessian=True)
    found = _find(model, points, cells, x, f, K, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "stress-gradient" and found[0].figures["hessian"]
    assert "written 1/3 J^(-2/3) g C^-1 where -1/3 J^(-2/3) g C^-1 belongs" in found[0].title
    assert "in the second derivative d2u/dC2 too" in found[0].title
    # nearby: the Hessian's linear terms with another factor than the gradient's
    f2, K2 = _demiray(split, model, k=-1.0, hessian=False)
    f3, K3 = _demiray(split, model, k=0.0, hessian=True)
    K_mix = K2 + 0.5 * (K3 - _demiray(split, model, k=0.0, hessian=False)[1])
    assert _find(model, points, cells, x, f2, K_mix, f_o, K_o, s) == []


def test_silent_where_mjed_cannot_split_the_model():
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=1)
    f, K = _neo(split, model, stress_mu=0.5)
    assert _find(model, points, cells, x, f, K, f_o, 1.001 * K_o, s) is None
    other = dataclasses.replace(model, mu=2.0 * model.mu)
    assert _find(other, points, cells, x, f, K, f_o, K_o, s) is None
