"""The Darcy pressure step: P1 matrices, the pressure's coupling force, Terzaghi."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh

import mjed
from comparisons.equivalence.taylor import taylor_rates
from comparisons.liver.terzaghi import run_terzaghi, terzaghi_pressure
from mjed.darcy import (
    DarcyParameters,
    FluidPressureForce,
    PressureSolver,
    cell_jacobians,
    p1_mass_matrix,
    p1_stiffness_matrix,
)


@pytest.fixture(scope="module")
def mesh():
    X, T = box_mesh(3, jitter=0.3)
    return mjed.TetMesh(X, T)


def test_matrix_identities(mesh):
    M, L = p1_mass_matrix(mesh), p1_stiffness_matrix(mesh)
    one = np.ones(mesh.n_nodes)
    assert np.isclose(one @ M @ one, mesh.volumes.sum(), rtol=1e-13)  # int 1 = volume
    assert np.abs(L @ one).max() < 1e-12 * abs(L).max()  # constants have no gradient
    x = mesh.points[:, 0]
    assert np.isclose(x @ L @ x, mesh.volumes.sum(), rtol=1e-12)  # int |grad x|^2
    assert np.allclose(p1_mass_matrix(mesh, lumped=True).diagonal(), M @ one)


@pytest.mark.oracle
def test_diffusion_matrices_match_the_ufl_oracle(mesh):
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx")
    from reference_fem.diffusion_oracle import diffusion_matrices

    M_o, L_o = diffusion_matrices(mesh.points, mesh.cells)
    for A, B in ((p1_mass_matrix(mesh), M_o), (p1_stiffness_matrix(mesh), L_o)):
        assert np.linalg.norm((A - B).toarray()) <= 1e-12 * np.linalg.norm(B.toarray())


def _state(mesh, seed=0):
    rng = np.random.default_rng(seed)
    return mesh.points + 0.05 * rng.standard_normal(mesh.points.shape)


def test_pressure_force_taylor_and_direction(mesh):
    fluid = FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3))
    fluid.P = np.random.default_rng(1).uniform(-100, 300, mesh.n_nodes)
    x = _state(mesh)
    v = np.random.default_rng(2).standard_normal(x.shape)
    f, K = fluid.force_and_stiffness(x)
    Kv = (K @ v.ravel()).reshape(v.shape)
    rates = taylor_rates(lambda y: fluid.force_and_stiffness(y)[0], -Kv, x, v, 1e-3)
    assert rates.min() >= 1.9
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    # A uniform positive pressure pushes the boundary outwards: f . x > 0 about the centre.
    fluid.P = np.full(mesh.n_nodes, 100.0)
    f = fluid.force_and_stiffness(mesh.points)[0]
    assert np.sum(f * (mesh.points - mesh.points.mean(axis=0))) > 0


@pytest.mark.oracle
def test_pressure_force_and_stiffness_match_the_ufl_oracle(mesh):
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx")
    from reference_fem.porous_energy import PorousOracle

    fluid = FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3))
    fluid.P = np.random.default_rng(1).uniform(-100, 300, mesh.n_nodes)
    oracle = PorousOracle(mesh.points, mesh.cells, with_pressure=True)
    oracle.set_pressure(fluid.P)
    x = _state(mesh)
    f, K = fluid.force_and_stiffness(x)
    f_o, K_o = oracle.force_and_stiffness(x)
    assert np.linalg.norm(f - f_o) <= 1e-10 * np.linalg.norm(f_o)
    assert np.linalg.norm((K - K_o).toarray()) <= 1e-10 * np.linalg.norm(K_o.toarray())


def test_sealed_compression_raises_pressure_and_conserves_fluid(mesh):
    params = DarcyParameters(K_lim=2000.0, kappa=1e-4)
    solver = PressureSolver(mesh, params)
    J_old = np.ones(mesh.n_cells)
    J_new = np.full(mesh.n_cells, 0.98)
    P = solver.step(np.zeros(mesh.n_nodes), J_old, J_new, 0.1)
    # Uniform compression of a sealed body: uniform P = -K_lim ln(0.98) (no gradient to diffuse).
    assert np.allclose(P, -2000.0 * np.log(0.98), rtol=1e-10)
    # Zero flux: diffusion conserves int P / K_lim + int ln J.
    rng = np.random.default_rng(0)
    J_rand = np.exp(0.02 * rng.standard_normal(mesh.n_cells))
    P2 = solver.step(P, J_new, J_rand, 0.1)
    M = solver.M
    one = np.ones(mesh.n_nodes)
    lhs = one @ M @ (P2 - P) / params.K_lim
    assert np.isclose(lhs, -np.sum(mesh.volumes * np.log(J_rand / J_new)), rtol=1e-10)


def test_drained_nodes_stay_at_zero_and_bad_input_is_refused(mesh):
    drained = np.flatnonzero(mesh.points[:, 2] > 0.99)
    solver = PressureSolver(mesh, DarcyParameters(2000.0, 1e-2), drained_nodes=drained)
    P = solver.step(np.zeros(mesh.n_nodes), np.ones(mesh.n_cells), np.full(mesh.n_cells, 0.95), 0.1)
    assert np.all(P[drained] == 0.0) and P.max() > 0
    with pytest.raises(ValueError, match="J_new"):
        solver.step(P, np.ones(mesh.n_cells), -np.ones(mesh.n_cells), 0.1)
    with pytest.raises(ValueError, match="dt"):
        solver.step(P, np.ones(mesh.n_cells), np.ones(mesh.n_cells), 0.0)
    with pytest.raises(ValueError, match="drained_nodes"):
        PressureSolver(mesh, DarcyParameters(2000.0, 1e-2), drained_nodes=[mesh.n_nodes])
    with pytest.raises(ValueError, match="K_lim"):
        DarcyParameters(0.0, 1.0)
    with pytest.raises(ValueError, match="kappa"):
        DarcyParameters(1.0, -1.0)


def test_accept_step_advances_from_the_last_accepted_J(mesh):
    fluid = FluidPressureForce(mesh, DarcyParameters(2000.0, 0.0))
    x = mesh.points * 0.99  # uniform compression, J = 0.99^3
    fluid.accept_step(x, 0.1)
    assert np.allclose(fluid.P, -2000.0 * 3 * np.log(0.99))
    fluid.accept_step(x, 0.1)  # no further change of J: undrained P stays
    assert np.allclose(fluid.P, -2000.0 * 3 * np.log(0.99))
    assert np.allclose(fluid.J_accepted, cell_jacobians(mesh, x))


def test_terzaghi_series_sanity():
    # At t = 0+ the series gives the initial pressure inside and 0 at the drained top.
    z = np.array([0.0, 0.5, 0.9])
    assert np.allclose(terzaghi_pressure(z, 1e-9, 1.0, 1.0, 2.0, n_terms=4000), 2.0, rtol=2e-2)
    assert abs(terzaghi_pressure(np.array([1.0]), 0.1, 1.0, 1.0, 2.0)[0]) < 1e-12


def test_terzaghi_consolidation_within_one_percent():
    """The coupled semi-implicit column against the series (relative L2 <= 1e-2), and the
    error falls with the time step (first order).
    """
    coarse = run_terzaghi(n_layers=20, dt=0.004, times=(0.05, 0.2, 0.5))
    errors = [t.relative_l2_error for t in coarse.times]
    assert max(errors) <= 1e-2 and coarse.worst_error == max(errors), errors
    fine = run_terzaghi(n_layers=20, dt=0.002, times=(0.05,))
    assert fine.times[0].relative_l2_error < 0.7 * errors[0]


@pytest.mark.oracle
def test_porous_solid_plus_pressure_in_one_pass_matches_the_ufl_oracle(mesh):
    """sigma_p = sigma(J) - P: the porous solid and the fluid pressure in one model."""
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx")
    from mjed.porous import PorousVolume
    from reference_fem.porous_energy import PorousOracle

    law = PorousVolume(0.5, 400.0, 2200.0)
    fluid = FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3), solid=law)
    fluid.P = np.random.default_rng(4).uniform(-100, 300, mesh.n_nodes)
    oracle = PorousOracle(mesh.points, mesh.cells, porous=law, with_pressure=True)
    oracle.set_pressure(fluid.P)
    x = mesh.points.copy()
    x[:, 0] *= 0.55 + 0.6 * mesh.points[:, 1]  # cells on both sides of J0
    J = cell_jacobians(mesh, x)
    assert (J < law.J0).any() and (J > law.J0).any()
    f, K = fluid.force_and_stiffness(x)
    f_o, K_o = oracle.force_and_stiffness(x)
    assert np.linalg.norm(f - f_o) <= 1e-10 * np.linalg.norm(f_o)
    assert np.linalg.norm((K - K_o).toarray()) <= 1e-10 * np.linalg.norm(K_o.toarray())


def test_linear_j_term_and_pressure_follow_assignment(mesh):
    """The pressure is the engine term -Pbar (J - 1): its derivatives, and the coefficient
    rewritten when P is set (and only then: P is read-only in place).
    """
    from mjed.darcy import LinearJ

    c = np.array([2.0, -3.0])
    f, df, d2f = LinearJ(c)(np.array([1.5, 0.5]))
    assert np.allclose(f, [1.0, 1.5]) and np.array_equal(df, c) and d2f == 0.0
    fluid = FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3))
    x = _state(mesh)
    assert np.abs(fluid.force_and_stiffness(x)[0]).max() == 0.0  # P = 0: no force
    fluid.P = np.full(mesh.n_nodes, 100.0)
    f100 = fluid.force_and_stiffness(x)[0]
    fluid.P = np.full(mesh.n_nodes, 200.0)
    assert (
        np.allclose(fluid.force_and_stiffness(x)[0], 2.0 * f100, rtol=1e-13)
        and np.abs(f100).max() > 0
    )
    with pytest.raises(ValueError):
        fluid.P[0] = 1.0
    with pytest.raises(ValueError, match="P must be"):
        fluid.P = np.zeros(mesh.n_nodes + 1)
    with pytest.raises(ValueError, match="P must be"):
        fluid.P = np.full(mesh.n_nodes, np.nan)


def test_solid_may_be_any_function_of_j(mesh):
    from mjed.porous import PorousVolume

    law = PorousVolume(0.5, 400.0, 2200.0)
    x = _state(mesh)
    f, K = FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3), solid=law).force_and_stiffness(x)
    f2, K2 = FluidPressureForce(
        mesh, DarcyParameters(2200.0, 1e-3), solid=lambda J: law(J)
    ).force_and_stiffness(x)
    assert np.array_equal(f, f2) and abs(K - K2).max() == 0.0
    with pytest.raises(TypeError, match="solid"):
        FluidPressureForce(mesh, DarcyParameters(2200.0, 1e-3), solid=1.0)
