"""Linear solvers of the implicit schemes: preconditioned CG, the SPD factor and its inertia
certificate, and the free block of the step matrix assembled from precomputed maps.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import MATERIALS, box_mesh, perturbed

import mjed
from mjed.linear_system import FreeBlock, same_pattern, sum_same_pattern
from mjed.mass import consistent_mass, lumped_mass
from mjed.solvers import (
    NotPositiveDefiniteError,
    SPDFactor,
    block_jacobi_preconditioner,
    conjugate_gradient,
    jacobi_preconditioner,
)


@pytest.fixture(scope="module")
def system():
    """A stiffness K (CSR, mesh pattern), a lumped and a consistent mass, free dofs (bottom
    fixed).
    """
    mesh = mjed.TetMesh(*box_mesh(3, jitter=0.2))
    x = perturbed(mesh.points, np.random.default_rng(1), 0.03)
    K = mjed.HyperelasticForceField(mesh, MATERIALS["NeoHookean"]).stiffness(x)
    bottom = np.flatnonzero(mesh.points[:, 2] == 0.0)
    free = np.setdiff1d(np.arange(3 * mesh.n_nodes), (3 * bottom[:, None] + np.arange(3)).ravel())
    return mesh, K, lumped_mass(mesh, 2.0), consistent_mass(mesh, 2.0), free


def _spd(system, mass=1.0):
    """A stiffness-dominated step matrix (as in a soft organ at a large time step)."""
    _, K, M, _, free = system
    return sp.csr_matrix((0.01 * mass * M + K)[free][:, free])


# ---------------------------------------------------------------- the factor
def test_spd_factor_solves_and_serves_as_an_exact_preconditioner(system):
    A = _spd(system)
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    factor = SPDFactor(A)
    np.testing.assert_allclose(factor(b), spla.spsolve(A.tocsc(), b), rtol=1e-10, atol=0)
    res = conjugate_gradient(A, b, tol=1e-10, preconditioner=factor)
    assert res.converged and res.iterations == 1
    # The factor of a nearby matrix (a later time step) is a close preconditioner.
    res = conjugate_gradient(_spd(system, 1.5), b, tol=1e-10, preconditioner=factor)
    jac = conjugate_gradient(_spd(system, 1.5), b, tol=1e-10)
    assert res.converged and res.iterations < jac.iterations / 3


def test_spd_factor_counts_the_negative_eigenvalues(system):
    """Sylvester: the pivots of the symmetric factorisation have the signs of the eigenvalues."""
    A = _spd(system)
    eig = np.linalg.eigvalsh(A.toarray())
    shift = 0.5 * (eig[40] + eig[41])  # exactly 41 eigenvalues below
    with pytest.raises(NotPositiveDefiniteError, match="41 of its") as info:
        SPDFactor(A - shift * sp.identity(A.shape[0], format="csr"))
    assert info.value.n_negative == 41 and info.value.n == A.shape[0]


# ---------------------------------------------------------------- preconditioned CG
@pytest.mark.parametrize(
    "make", [None, jacobi_preconditioner, block_jacobi_preconditioner, SPDFactor]
)
def test_every_preconditioner_reaches_the_solution(system, make):
    A = _spd(system)
    x_true = np.random.default_rng(3).standard_normal(A.shape[0])
    b = A @ x_true
    res = conjugate_gradient(
        A, b, tol=1e-12, max_iterations=5000, preconditioner=None if make is None else make(A)
    )
    assert res.converged and res.reason == "converged" and res.residual <= 1e-12
    np.testing.assert_allclose(res.x, x_true, rtol=0, atol=1e-8 * np.abs(x_true).max())


def test_block_jacobi_inverts_the_node_blocks(system):
    A = _spd(system)
    r = np.random.default_rng(4).standard_normal(A.shape[0])
    dense = A.toarray()
    expected = np.concatenate(
        [
            np.linalg.solve(dense[i : i + 3, i : i + 3], r[i : i + 3])
            for i in range(0, A.shape[0], 3)
        ]
    )
    np.testing.assert_allclose(block_jacobi_preconditioner(A)(r), expected, rtol=1e-12)
    with pytest.raises(ValueError, match="multiple of the block size"):
        block_jacobi_preconditioner(A[:-1, :-1])


def test_cg_reports_indefinite_matrices_and_preconditioners():
    A = sp.diags([2.0, -1.0, 3.0], format="csr")
    res = conjugate_gradient(A, np.array([0.0, 1.0, 0.0]), preconditioner=lambda r: r.copy())
    assert not res.converged and res.reason == "negative_curvature"
    res = conjugate_gradient(sp.identity(3, format="csr"), np.ones(3), preconditioner=lambda r: -r)
    assert not res.converged and res.reason == "preconditioner_indefinite"


def test_cg_returns_a_first_guess_that_already_solves(system):
    A = _spd(system)
    x = np.random.default_rng(5).standard_normal(A.shape[0])
    res = conjugate_gradient(A, A @ x, tol=1e-8, x0=x)
    assert res.converged and res.iterations == 0
    np.testing.assert_array_equal(res.x, x)


# ---------------------------------------------------------------- the free block
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_free_block_equals_the_sliced_sum(system, mass):
    _, K, M_lumped, M_consistent, free = system
    M = M_lumped if mass == "lumped" else M_consistent
    block = FreeBlock(M, free)
    for a, b in ((1.03, 0.0009), (1.0, 0.25)):
        got = block(a, K, b)
        want = sp.csr_matrix((a * M + b * K)[free][:, free])
        assert block.fast and abs(got - want).max() <= 1e-14 * abs(want).max()
    # The maps are reused for a new K with the same pattern, and follow a new pattern.
    K2 = K.copy()
    K2.data *= 1.7
    assert abs(block(1.0, K2, 0.5) - (M + 0.5 * K2)[free][:, free]).max() <= 1e-14 * abs(K2).max()
    K3 = sp.csr_matrix(K + sp.identity(K.shape[0]) * 0.0 + sp.eye(K.shape[0], k=3))
    got = block(1.0, K3, 0.5)
    assert abs(got - (M + 0.5 * K3)[free][:, free]).max() <= 1e-14 * abs(K3).max()


def test_free_block_falls_back_when_the_mass_lies_outside_the_pattern(system):
    _, K, M, _, free = system
    M_wide = sp.csr_matrix(
        M + sp.eye(M.shape[0], k=M.shape[0] - 1)
    )  # a corner entry K does not store
    block = FreeBlock(M_wide, free)
    got = block(1.0, K, 0.5)
    assert not block.fast
    assert abs(got - (M_wide + 0.5 * K)[free][:, free]).max() <= 1e-14 * abs(K).max()


def test_summing_stiffnesses_of_one_pattern_adds_their_data(system):
    _, K, M, _, _ = system
    K2 = K.copy()
    K2.data = np.random.default_rng(6).standard_normal(K2.nnz)
    assert same_pattern(K, K2) and not same_pattern(K, M)
    for other in (K2, M, M.tocoo()):
        assert abs(sum_same_pattern(K, other) - (K + other)).max() == 0.0


def test_a_single_precision_factor_preconditions_but_its_pivots_see_the_rounded_matrix(system):
    A = _spd(system)
    b = np.random.default_rng(7).standard_normal(A.shape[0])
    single = SPDFactor(A, single=True)
    exact = spla.spsolve(A.tocsc(), b)
    np.testing.assert_allclose(single(b), exact, rtol=0, atol=1e-4 * np.abs(exact).max())
    assert single(b).dtype == np.float64
    res = conjugate_gradient(
        A, b, tol=1e-12, preconditioner=single
    )  # CG in double reaches any tolerance
    assert res.converged and res.iterations <= 4
    # SPD in double precision, singular once rounded to single: why the integrator retries in
    # double.
    close = sp.csr_matrix(np.array([[1.0, 1.0 - 1e-10], [1.0 - 1e-10, 1.0]]))
    SPDFactor(close)
    with pytest.raises(NotPositiveDefiniteError):
        SPDFactor(close, single=True)


def test_linear_solver_options_are_one_validated_frozen_object():
    import dataclasses

    from mjed.solvers import LinearSolverOptions

    opts = LinearSolverOptions(
        cg_tol=1e-6, max_iterations=50, preconditioner="factorized", factor_precision="single"
    )
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.cg_tol = 1.0
    assert opts == LinearSolverOptions(
        cg_tol=1e-6, max_iterations=50, preconditioner="factorized", factor_precision="single"
    )
    assert "kept single-precision sparse LU" in opts.label() and "rtol 1e-06" in opts.label()
    assert "direct" in LinearSolverOptions(solver="direct").label()
    for bad, word in [
        (dict(cg_tol=0.0), "cg_tol"),
        (dict(cg_tol=float("nan")), "cg_tol"),
        (dict(cg_tol=True), "cg_tol"),
        (dict(max_iterations=0), "max_iterations"),
        (dict(max_iterations=2.5), "max_iterations"),
        (dict(preconditioner="ilu"), "preconditioner"),
        (dict(solver="gmres"), "solver"),
    ]:
        with pytest.raises(ValueError, match=f"LinearSolverOptions.{word}"):
            LinearSolverOptions(**bad)
