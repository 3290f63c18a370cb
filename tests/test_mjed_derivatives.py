"""Derivative checks of the MJED engine that need no oracle: Taylor rates, central
differences, rest state, symmetry, invariance and the patch test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from conftest import box_mesh, perturbed, random_tetrahedron

import mjed
from comparisons.equivalence.taylor import energy_force_rates, force_stiffness_rates
from mjed.materials.base import Material
from mjed.terms import I1Power, JPower, LinearI2, Log, LogPolynomial, Power, Term, TermGroup, Unity


@pytest.fixture
def jittered_field(material):
    points, cells = box_mesh(2, jitter=0.3, seed=3)
    return mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)


def test_taylor_energy_force(jittered_field, rng):
    x = perturbed(jittered_field.mesh.points, rng)
    v = rng.standard_normal(x.shape)
    rates = energy_force_rates(jittered_field, x, v, eps0=1e-3)
    assert rates.min() >= 1.9, rates


def test_taylor_force_stiffness(jittered_field, rng):
    x = perturbed(jittered_field.mesh.points, rng)
    v = rng.standard_normal(x.shape)
    rates = force_stiffness_rates(jittered_field, x, v, eps0=1e-3)
    assert rates.min() >= 1.9, rates


def test_a_wrong_derivative_fails_the_taylor_test(jittered_field, rng):
    # The check must be able to fail: a stiffness off by 1 % gives rate ~1.
    x = perturbed(jittered_field.mesh.points, rng)
    v = rng.standard_normal(x.shape)
    from comparisons.equivalence.taylor import taylor_rates

    Kv = 1.01 * (jittered_field.stiffness(x) @ v.ravel()).reshape(v.shape)
    rates = taylor_rates(jittered_field.force, -Kv, x, v, eps0=1e-4)
    assert rates.min() < 1.5


def _central_differences(field, x, h: float = 1e-6):
    """Force (12,) and stiffness (12, 12) of a one-cell field by central differences of its
    energy and force.
    """
    f_fd = np.zeros(12)
    K_fd = np.zeros((12, 12))
    for k in range(12):
        e = np.zeros(12)
        e[k] = h
        e = e.reshape(4, 3)
        f_fd[k] = -(field.energy(x + e) - field.energy(x - e)) / (2 * h)
        K_fd[:, k] = -(field.force(x + e) - field.force(x - e)).ravel() / (2 * h)
    return f_fd, K_fd


def test_central_differences_single_tet(material, rng):
    P, cells = random_tetrahedron(rng)
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), material)
    x = perturbed(P, rng, 0.1)
    f = field.force(x)
    K = field.stiffness(x).toarray()
    f_fd, K_fd = _central_differences(field, x)
    assert np.linalg.norm(f.ravel() - f_fd) <= 1e-7 * np.linalg.norm(f_fd)
    assert np.linalg.norm(K - K_fd) <= 1e-7 * np.linalg.norm(K_fd)


def test_rest_state_has_zero_energy_and_force(material):
    points, cells = box_mesh(2, jitter=0.3)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)
    scale = np.abs(field.stiffness(points).data).max()
    assert abs(field.energy(points)) <= 1e-14 * scale
    assert np.abs(field.force(points)).max() <= 1e-13 * scale


def test_stiffness_is_symmetric(jittered_field, rng):
    K = jittered_field.stiffness(perturbed(jittered_field.mesh.points, rng))
    assert abs(K - K.T).max() <= 1e-13 * abs(K).max()


def test_element_stiffness_assembles_to_global(jittered_field, rng):
    x = perturbed(jittered_field.mesh.points, rng)
    Ke = jittered_field.element_stiffness(x)
    assert Ke.shape == (jittered_field.mesh.n_cells, 12, 12)
    dense = np.zeros((3 * jittered_field.mesh.n_nodes,) * 2)
    dofs = (3 * jittered_field.mesh.cells[:, :, None] + np.arange(3)).reshape(-1, 12)
    for d, k in zip(dofs, Ke):
        dense[np.ix_(d, d)] += k
    assert np.allclose(
        jittered_field.stiffness(x).toarray(), dense, rtol=0, atol=1e-13 * np.abs(dense).max()
    )


def test_force_and_stiffness_match_separate_calls(jittered_field, rng):
    x = perturbed(jittered_field.mesh.points, rng)
    f, K = jittered_field.force_and_stiffness(x)
    assert np.array_equal(f, jittered_field.force(x))
    assert (K != jittered_field.stiffness(x)).nnz == 0


def test_forces_balance_and_rotate(jittered_field, rng):
    x = perturbed(jittered_field.mesh.points, rng)
    f = jittered_field.force(x)
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() <= 1e-12 * scale  # translation
    assert np.abs(np.cross(x, f).sum(axis=0)).max() <= 1e-12 * scale  # rotation
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    assert np.allclose(
        jittered_field.force(x @ Q.T), f @ Q.T, rtol=0, atol=1e-12 * scale
    )  # objectivity


def test_patch_test_interior_forces_vanish(material, rng):
    points, cells = box_mesh(3, jitter=0.3, seed=5)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)
    A = np.eye(3) + 0.15 * rng.standard_normal((3, 3))
    assert np.linalg.det(A) > 0
    x = points @ A.T + rng.standard_normal(3)
    f = field.force(x)
    interior = np.all((points > 1e-12) & (points < 1 - 1e-12), axis=1)
    assert interior.sum() == 8
    assert np.abs(f[interior]).max() <= 1e-12 * np.abs(f).max()


@pytest.mark.parametrize("function", ["log", "power", "power_integer"])
def test_smooth_function_of_a_sum_has_consistent_derivatives(function, rng):
    """A group c phi(u) with phi = ln(a + u) or (a + u)^p: force and stiffness are the
    derivatives of the energy (central differences), including the rank-one c phi'' term.
    """
    phi = {"log": Log(0.8), "power": Power(2.5, 0.3), "power_integer": Power(3.0, -0.5)}[function]

    @dataclass(frozen=True)
    class Made(Material):
        def decomposition(self):
            u = (Term(JPower(-2.0 / 3.0), I1Power(0.2)), Term(JPower(-4.0 / 3.0), LinearI2(0.1)))
            return (
                TermGroup(u, coefficient=1.7, function=phi),
                TermGroup((Term(LogPolynomial(2.0), Unity()),)),
            )

    P, cells = random_tetrahedron(rng)
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), Made())
    x = perturbed(P, rng, 0.1)
    f, K = field.force(x), field.stiffness(x).toarray()
    f_fd, K_fd = _central_differences(field, x)
    assert np.linalg.norm(f.ravel() - f_fd) <= 1e-7 * np.linalg.norm(f_fd)
    assert np.linalg.norm(K - K_fd) <= 1e-7 * np.linalg.norm(K_fd)
    # a Hessian: symmetric
    assert np.linalg.norm(K - K.T) <= 1e-12 * np.linalg.norm(K)


def test_a_log_group_beyond_its_domain_gives_nan_not_a_finite_force():
    """Gent past its locking stretch (I1b - 3 >= Jm): W is undefined, and so are the force and
    the stiffness (a finite force there would push the wrong way).
    """
    P, cells = box_mesh(1)
    gent = mjed.materials.Gent(mu=1.0, Jm=0.5, k0=3.0)
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), gent)
    x = P * np.array([2.0, 0.7, 0.7])  # I1b - 3 of about 1.4 in every cell
    with np.errstate(all="ignore"):
        f, K = field.force_and_stiffness(x)
    assert np.isnan(f).all() and np.isnan(K.data).all() and np.isnan(field.energy(x))
    assert np.isfinite(field.force(P * np.array([1.1, 0.95, 0.95]))).all()
