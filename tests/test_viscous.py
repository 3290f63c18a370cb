"""Prony visco-hyperelasticity: parameters, the history recursion against closed forms,
derivatives at fixed history, and the UFL oracle of one viscous step.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, box_mesh, perturbed, random_tetrahedron

import mjed
from comparisons.equivalence.taylor import force_stiffness_rates
from mjed.evaluation import Want
from mjed.materials import StVenantKirchhoff
from mjed.viscous import Prony, ViscoHyperelasticForceField, prony_coefficients

PRONY = Prony((0.235, 0.333), (0.27, 0.03))


# ---------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "alphas, taus, word",
    [
        ((-0.1, 0.2), (1.0, 2.0), "alphas[0]"),
        ((0.5, 0.5), (1.0, 2.0), "sum(alphas)"),
        ((0.2, 0.3), (1.0, 0.0), "taus[1]"),
        ((0.2, 0.3), (1.0, -2.0), "taus[1]"),
        ((0.2, np.nan), (1.0, 2.0), "alphas[1]"),
        ((0.2,), (1.0, np.inf), "equal lengths"),
        ((0.2,), (np.inf,), "taus[0]"),
        ((), (), "at least one"),
    ],
)
def test_invalid_prony_parameters_are_refused_by_name(alphas, taus, word):
    with pytest.raises(
        ValueError,
        match=word.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]"),
    ):
        Prony(alphas, taus)


def test_coefficients_follow_the_paper():
    a, b = prony_coefficients(PRONY, 0.01)
    np.testing.assert_allclose(a, [0.01 * 0.235 / 0.28, 0.01 * 0.333 / 0.04], rtol=1e-15)
    np.testing.assert_allclose(b, [0.27 / 0.28, 0.03 / 0.04], rtol=1e-15)
    with pytest.raises(ValueError, match="dt"):
        prony_coefficients(PRONY, 0.0)


def test_moduli_limits():
    assert PRONY.complex_modulus(0.0) == pytest.approx(PRONY.alpha_inf)
    assert abs(PRONY.complex_modulus(1e9) - 1.0) < 1e-7
    # The backward-Euler modulus tends to the continuous one as dt -> 0, at first order.
    w = 5.0
    errs = [abs(PRONY.discrete_modulus(w, dt) - PRONY.complex_modulus(w)) for dt in (1e-3, 5e-4)]
    assert errs[0] / errs[1] == pytest.approx(2.0, rel=0.05)


# ---------------------------------------------------------------- relaxation of one element
def _stretched(P, e):
    """Positions of the homogeneous deformation with Green-Lagrange strain diag(e, 0, 0)."""
    F = np.diag([np.sqrt(1.0 + 2.0 * e), 1.0, 1.0])
    return P @ F.T


def test_step_relaxation_matches_the_discrete_closed_form_to_round_off():
    P, cells = random_tetrahedron(np.random.default_rng(3))
    mat = StVenantKirchhoff(mu=770.0, lam=3000.0)
    dt = 0.01
    vf = ViscoHyperelasticForceField(mjed.TetMesh(P, cells), mat, prony=PRONY, dt=dt)
    x = _stretched(P, 0.2)
    S_h = mjed.HyperelasticForceField(vf.mesh, mat).evaluate(x, want=Want.STRESS).pk2[0]
    _, b = prony_coefficients(PRONY, dt)
    for n in range(1, 60):
        S_v = vf.stress(x)[0]  # the stress of step n, history of step n - 1
        expected = 1.0 - sum(al * (1.0 - bi**n) for al, bi in zip(PRONY.alphas, b))
        np.testing.assert_allclose(S_v, expected * S_h, rtol=1e-13, atol=1e-13 * np.abs(S_h).max())
        vf.accept_step(x)


def test_ramp_and_hold_relaxation_converges_to_the_prony_closed_form():
    """Green-Lagrange strain ramped linearly (so S_h of StVK is linear in t) over t_r, then held:
    sigma(t) / sigma_0 = alpha_inf + sum alpha_i (tau_i / t_r)(e^(-(t - t_r)/tau_i) - e^(-t/tau_i)).
    """
    P, cells = random_tetrahedron(np.random.default_rng(4))
    mat = StVenantKirchhoff(mu=770.0, lam=3000.0)
    mesh = mjed.TetMesh(P, cells)
    t_r, t_end, e0 = 0.1, 0.5, 0.3
    S_final = (
        mjed.HyperelasticForceField(mesh, mat).evaluate(_stretched(P, e0), want=Want.STRESS).pk2[0]
    )

    def error(dt):
        vf = ViscoHyperelasticForceField(mesh, mat, prony=PRONY, dt=dt)
        n_steps = int(round(t_end / dt))
        for n in range(1, n_steps + 1):
            t = n * dt
            x = _stretched(P, e0 * min(t / t_r, 1.0))
            S_v = vf.stress(x)[0]
            vf.accept_step(x)
        closed = PRONY.alpha_inf + sum(
            al * tau / t_r * (np.exp(-(t_end - t_r) / tau) - np.exp(-t_end / tau))
            for al, tau in zip(PRONY.alphas, PRONY.taus)
        )
        return np.abs(S_v - closed * S_final).max() / np.abs(S_final).max()

    e1, e2 = error(1e-3), error(5e-4)
    assert e1 < 2e-3
    assert e1 / e2 == pytest.approx(2.0, rel=0.1)  # backward Euler: first order


# ---------------------------------------------------------------- derivatives at fixed history
def _with_history(mesh, material, rng, *, prony=PRONY, dt=0.02, scale=0.05):
    vf = ViscoHyperelasticForceField(mesh, material, prony=prony, dt=dt)
    for _ in range(2):
        vf.accept_step(perturbed(mesh.points, rng, scale))
    return vf


def test_force_and_stiffness_are_consistent_at_fixed_history(material):
    rng = np.random.default_rng(0)
    mesh = mjed.TetMesh(*box_mesh(2, jitter=0.2))
    vf = _with_history(mesh, material, rng)
    assert np.abs(vf.gammas).max() > 0  # the geometric term of the history is exercised
    x = perturbed(mesh.points, rng, 0.05)
    v = rng.standard_normal(x.shape)
    rates = force_stiffness_rates(vf, x, v, 1e-2)
    assert rates.min() >= 1.9, rates
    K = vf.stiffness(x)
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    h = 1e-6
    fd = (vf.force(x + h * v) - vf.force(x - h * v)) / (2 * h)
    assert np.linalg.norm(fd.ravel() + K @ v.ravel()) <= 1e-7 * np.linalg.norm(K @ v.ravel())


def test_a_wrong_history_term_fails_the_taylor_test():
    """The Taylor check can fail: drop the history's geometric stiffness and the rate falls to 1."""
    rng = np.random.default_rng(1)
    mesh = mjed.TetMesh(*box_mesh(2, jitter=0.2))
    vf = _with_history(mesh, MATERIALS["NeoHookean"], rng, scale=0.1)
    x = perturbed(mesh.points, rng, 0.05)
    v = rng.standard_normal(x.shape)

    class WithoutHistoryStiffness:
        force = staticmethod(vf.force)

        @staticmethod
        def stiffness(y):
            a, _ = prony_coefficients(vf.prony, vf.dt)
            return (1.0 - a.sum()) * mjed.HyperelasticForceField(
                mesh, MATERIALS["NeoHookean"]
            ).stiffness(y)

    assert force_stiffness_rates(WithoutHistoryStiffness, x, v, 1e-2).min() < 1.5


def test_zero_history_is_the_scaled_hyperelastic_body():
    rng = np.random.default_rng(2)
    mesh = mjed.TetMesh(*box_mesh(2, jitter=0.2))
    mat = MATERIALS["MooneyRivlin"]
    vf = ViscoHyperelasticForceField(mesh, mat, prony=PRONY, dt=0.05)
    field = mjed.HyperelasticForceField(mesh, mat)
    x = perturbed(mesh.points, rng, 0.1)
    a, _ = prony_coefficients(PRONY, 0.05)
    f, K = vf.force_and_stiffness(x)
    np.testing.assert_allclose(
        f, (1 - a.sum()) * field.force(x), rtol=1e-13, atol=1e-13 * np.abs(f).max()
    )
    assert abs(K - (1 - a.sum()) * field.stiffness(x)).max() <= 1e-13 * abs(K).max()


# ---------------------------------------------------------------- history bookkeeping
def test_history_moves_only_on_accept_and_can_be_restored():
    rng = np.random.default_rng(5)
    mesh = mjed.TetMesh(*box_mesh(1))
    vf = ViscoHyperelasticForceField(mesh, MATERIALS["NeoHookean"], prony=PRONY)
    with pytest.raises(ValueError, match="prepare_step"):
        vf.force(mesh.points)
    vf.prepare_step(0.01)
    x = perturbed(mesh.points, rng, 0.1)
    before = vf.force(x)
    vf.force_and_stiffness(perturbed(mesh.points, rng, 0.1))
    np.testing.assert_array_equal(vf.force(x), before)  # evaluating does not commit
    saved = vf.save_history()
    vf.accept_step(x)
    assert vf.steps == 1 and not np.array_equal(vf.force(x), before)
    vf.restore_history()
    assert vf.steps == 0
    np.testing.assert_array_equal(vf.force(x), before)
    vf.accept_step(x, 0.02)
    assert vf.dt == 0.02
    vf.restore_history(saved)
    np.testing.assert_array_equal(vf.gammas, 0.0)


def test_constructor_and_inverted_errors():
    P, cells = random_tetrahedron(np.random.default_rng(6))
    mesh = mjed.TetMesh(P, cells)
    mat = MATERIALS["NeoHookean"]
    with pytest.raises(ValueError, match="material"):
        ViscoHyperelasticForceField(mesh, prony=PRONY)
    with pytest.raises(TypeError, match="Prony"):
        ViscoHyperelasticForceField(mesh, mat, prony=(0.1, 1.0))
    field = mjed.HyperelasticForceField(mesh, mat)
    vf = ViscoHyperelasticForceField(field, prony=PRONY, dt=0.1)
    flipped = P.copy()
    flipped[3] = P[:3].mean(axis=0) - (P[3] - P[:3].mean(axis=0))
    with pytest.raises(mjed.InvertedElementError, match="cell 0"):
        vf.force_and_stiffness(flipped)
    with pytest.raises(ValueError, match="non-finite"):
        vf.force(np.full_like(P, np.nan))


# ---------------------------------------------------------------- the UFL oracle
@pytest.mark.oracle
@pytest.mark.parametrize("name", ["StVenantKirchhoff", "NeoHookean", "ArrudaBoyce", "Costa"])
def test_one_viscous_step_agrees_with_the_ufl_oracle(name):
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx (Debian: python3-dolfinx)")
    from common.tolerances import FORCE_TOL, STIFFNESS_TOL
    from reference_fem.viscous_oracle import ViscousUFLOracle

    rng = np.random.default_rng(7)
    points, cells = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(points, cells)
    material = MATERIALS[name]
    vf = _with_history(mesh, material, rng, dt=0.013)
    oracle = ViscousUFLOracle(points, cells, material, PRONY.alphas, PRONY.taus)
    x = perturbed(points, rng, 0.05)
    f, K = vf.force_and_stiffness(x)
    f_o, K_o = oracle.force_and_stiffness(x, vf.gammas, 0.013)
    assert np.linalg.norm(f - f_o) <= FORCE_TOL * np.linalg.norm(f_o)
    assert np.linalg.norm((K - K_o).toarray()) <= STIFFNESS_TOL * np.linalg.norm(K_o.toarray())
    # Not vacuous: a history one part in 1e6 off is seen.
    f_off, _ = oracle.force_and_stiffness(x, vf.gammas * (1 + 1e-6), 0.013)
    assert np.linalg.norm(f - f_off) > 100 * FORCE_TOL * np.linalg.norm(f_off)
