"""Implicit Euler: the documented linear system, free fall, a decaying oscillation, Newton,
quasi-static prescribed motion with reactions, mass matrices, and every failure mode.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import MATERIALS, box_mesh, perturbed

import mjed
from mjed.integrator import ImplicitEuler, Prescribed
from mjed.integrator import LinearSolverOptions as S
from mjed.mass import consistent_mass, lumped_mass, nodal_masses

G = np.array([0.0, 0.0, -9.81])


@pytest.fixture(scope="module")
def cube():
    return mjed.TetMesh(*box_mesh(2, jitter=0.2))


def _field(mesh, name="NeoHookean"):
    return mjed.HyperelasticForceField(mesh, MATERIALS[name])


def _bottom(mesh):
    return np.flatnonzero(mesh.points[:, 2] == 0.0)


# ---------------------------------------------------------------- mass
@pytest.mark.parametrize("kind", ["lumped", "consistent"])
def test_mass_matrices_carry_the_body_mass(cube, kind):
    M = (lumped_mass if kind == "lumped" else consistent_mass)(cube, 3.0)
    total = 3.0 * cube.volumes.sum()
    for c in range(3):
        e = np.zeros((cube.n_nodes, 3))
        e[:, c] = 1.0
        assert e.ravel() @ (M @ e.ravel()) == pytest.approx(total, rel=1e-13)
    assert abs(M - M.T).max() <= 1e-15 * abs(M).max()
    assert np.linalg.eigvalsh(M.toarray()).min() > 0
    np.testing.assert_allclose(
        np.asarray(consistent_mass(cube, 3.0).sum(axis=1)).ravel(),
        np.repeat(nodal_masses(cube, 3.0), 3),
        rtol=1e-13,
    )


def test_mass_refuses_bad_densities(cube):
    with pytest.raises(ValueError, match="density"):
        lumped_mass(cube, -1.0)
    with pytest.raises(ValueError, match="cell 2"):
        consistent_mass(cube, np.r_[1.0, 1.0, np.nan, np.ones(cube.n_cells - 3)])
    with pytest.raises(ValueError, match="shape"):
        lumped_mass(cube, np.ones(3))


# ---------------------------------------------------------------- the scheme itself
def test_one_step_solves_the_documented_linear_system(cube):
    """A dv = dt (f + f_ext - D v0 - dt K v0), A = (1 + dt rM) M + (dt^2 + dt rK) K, on the free
    dofs.
    """
    rng = np.random.default_rng(0)
    field = _field(cube)
    x0 = perturbed(cube.points, rng, 0.05)
    v0 = 0.3 * rng.standard_normal(x0.shape)
    fixed = _bottom(cube)
    v0[fixed] = 0.0
    dt, rM, rK, rho = 0.02, 0.7, 0.01, 2.0
    integ = ImplicitEuler(
        cube,
        field,
        rho,
        dt=dt,
        mass="consistent",
        fixed_nodes=fixed,
        rayleigh_mass=rM,
        rayleigh_stiffness=rK,
        x0=x0,
        v0=v0,
        solver=S(cg_tol=1e-14),
    )
    report = integ.step()

    f, K = field.force_and_stiffness(x0)
    M = consistent_mass(cube, rho)
    f_ext = M @ np.tile(G, cube.n_nodes)
    D = rM * M + rK * K
    A = (1 + dt * rM) * M + (dt**2 + dt * rK) * K
    rhs = dt * (f.ravel() + f_ext - D @ v0.ravel() - dt * (K @ v0.ravel()))
    free = np.setdiff1d(np.arange(3 * cube.n_nodes), (3 * fixed[:, None] + np.arange(3)).ravel())
    dv = np.zeros(3 * cube.n_nodes)
    dv[free] = spla.spsolve(sp.csc_matrix(A[free][:, free]), rhs[free])
    v1 = v0.ravel() + dv
    np.testing.assert_allclose(integ.v.ravel(), v1, rtol=0, atol=1e-11 * np.abs(v1).max())
    np.testing.assert_allclose(integ.x.ravel(), x0.ravel() + dt * v1, rtol=0, atol=1e-13)
    # The reaction closes the balance on the fixed rows: M dv = dt (f_lin + f_ext - D v1 + R).
    R = ((A @ dv - rhs) / dt).reshape(-1, 3)
    np.testing.assert_allclose(report.reaction[fixed], R[fixed], atol=1e-9 * np.abs(R).max())
    assert np.all(report.reaction[np.setdiff1d(np.arange(cube.n_nodes), fixed)] == 0.0)
    assert report.step == 1 and integ.t == pytest.approx(dt) and report.newton_iterations == 1


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_free_fall_without_supports_has_acceleration_g(cube, mass):
    integ = ImplicitEuler(cube, _field(cube), 1000.0, dt=0.01, mass=mass, solver=S(cg_tol=1e-14))
    n = 25
    integ.run(n)
    np.testing.assert_allclose(
        integ.v, np.tile(n * 0.01 * G, (cube.n_nodes, 1)), rtol=0, atol=1e-10
    )
    # Backward Euler positions: x_n = X + dt^2 g n (n + 1) / 2; the body stays undeformed.
    np.testing.assert_allclose(
        integ.x - cube.points,
        np.tile(0.01**2 * G * n * (n + 1) / 2, (cube.n_nodes, 1)),
        rtol=0,
        atol=1e-12,
    )
    assert np.abs(_field(cube).force(integ.x)).max() < 1e-9


def test_a_damped_oscillation_decays(cube):
    field = _field(cube)
    v0 = np.zeros_like(cube.points)
    v0[:, 0] = 0.5 * cube.points[:, 2]  # swing the top sideways, bottom clamped
    integ = ImplicitEuler(
        cube,
        field,
        1.0,
        dt=0.02,
        gravity=None,
        fixed_nodes=_bottom(cube),
        v0=v0,
        rayleigh_mass=1.0,
        newton_iterations=8,
        newton_tol=1e-10,
        solver=S(cg_tol=1e-12),
    )
    energy = [integ.kinetic_energy() + field.energy(integ.x)]
    top_velocity = []
    for _ in range(250):
        integ.step()
        energy.append(integ.kinetic_energy() + field.energy(integ.x))
        top_velocity.append(integ.v[cube.points[:, 2] == 1.0, 0].mean())
    energy = np.array(energy)
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])  # backward Euler and damping only dissipate
    assert energy[-1] < 0.05 * energy[0]
    # ... and it did oscillate: the top's sideways velocity changes sign more than once.
    assert np.count_nonzero(np.diff(np.sign(top_velocity))) >= 2


def test_newton_solves_the_nonlinear_backward_euler_equation(cube):
    field = _field(cube)
    integ = ImplicitEuler(
        cube,
        field,
        1.0,
        dt=0.05,
        fixed_nodes=_bottom(cube),
        rayleigh_stiffness=0.01,
        newton_iterations=10,
        newton_tol=1e-11,
        solver=S(cg_tol=1e-13),
        gravity=(0.0, 0.0, -30.0),
    )
    report = integ.step()
    assert report.newton_iterations >= 2 and report.newton_residual <= 1e-11
    f, K = field.force_and_stiffness(integ.x)
    M = lumped_mass(cube, 1.0)
    v1 = integ.v.ravel()
    r = 0.05 * (f.ravel() + M @ np.tile([0, 0, -30.0], cube.n_nodes) - 0.01 * (K @ v1)) - M @ v1
    free = np.setdiff1d(np.arange(cube.n_nodes), _bottom(cube))
    first = 0.05 * np.linalg.norm((M @ np.tile([0, 0, -30.0], cube.n_nodes)).reshape(-1, 3)[free])
    assert np.linalg.norm(r.reshape(-1, 3)[free]) <= 1e-10 * first
    # The one-solve (SOFA) step is a different, linearised answer.
    sofa = ImplicitEuler(
        cube,
        field,
        1.0,
        dt=0.05,
        fixed_nodes=_bottom(cube),
        rayleigh_stiffness=0.01,
        solver=S(cg_tol=1e-13),
        gravity=(0.0, 0.0, -30.0),
    )
    sofa.step()
    assert np.abs(sofa.x - integ.x).max() > 1e-8


def test_quasi_static_prescribed_motion_and_balanced_reactions(cube):
    bottom = _bottom(cube)
    top = np.flatnonzero(cube.points[:, 2] == 1.0)
    lift = Prescribed(top, lambda t: np.tile([0.0, 0.05 * t, 0.1 * t], (len(top), 1)))
    field = _field(cube)
    integ = ImplicitEuler(
        cube,
        field,
        0.0,
        dt=0.5,
        gravity=None,
        fixed_nodes=bottom,
        prescribed=lift,
        newton_iterations=20,
        newton_tol=1e-10,
        solver=S(cg_tol=1e-13),
    )
    reports = integ.run(2)
    np.testing.assert_allclose(
        integ.x[top], cube.points[top] + [0.0, 0.05, 0.1], rtol=0, atol=1e-14
    )
    np.testing.assert_array_equal(integ.x[bottom], cube.points[bottom])
    R = reports[-1].reaction
    f = field.force(integ.x)
    free = np.setdiff1d(np.arange(cube.n_nodes), np.r_[bottom, top])
    assert np.abs(f[free]).max() <= 1e-8 * np.abs(f).max()  # static equilibrium inside
    np.testing.assert_allclose(
        R[np.r_[bottom, top]], -f[np.r_[bottom, top]], atol=1e-8 * np.abs(f).max()
    )
    assert (
        np.abs(R.sum(axis=0)).max() <= 1e-8 * np.abs(R).max()
    )  # no external load: reactions balance
    assert R[top, 2].sum() > 0  # the upper plate pulls the stretched block up


def test_models_are_summed_and_told_about_steps(cube):
    calls = []

    class Spy:
        def __init__(self, inner):
            self.inner = inner

        def force_and_stiffness(self, x):
            return self.inner.force_and_stiffness(x)

        def prepare_step(self, dt):
            calls.append(("prepare", dt))

        def accept_step(self, x, dt):
            calls.append(("accept", dt))

    field = _field(cube)
    one = ImplicitEuler(
        cube,
        [Spy(field), Spy(field)],
        1.0,
        dt=0.01,
        fixed_nodes=_bottom(cube),
        solver=S(cg_tol=1e-13),
    )
    one.step()
    assert calls == [("prepare", 0.01), ("prepare", 0.01), ("accept", 0.01), ("accept", 0.01)]
    doubled = mjed.HyperelasticForceField(
        cube, type(MATERIALS["NeoHookean"])(mu=2 * 1.3, lam=2 * 2.1)
    )
    two = ImplicitEuler(
        cube, doubled, 1.0, dt=0.01, fixed_nodes=_bottom(cube), solver=S(cg_tol=1e-13)
    )
    two.step()
    np.testing.assert_allclose(one.x, two.x, rtol=0, atol=1e-12)


def test_a_viscous_model_commits_its_history_through_the_integrator(cube):
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    vf = ViscoHyperelasticForceField(cube, MATERIALS["NeoHookean"], prony=Prony((0.3,), (0.1,)))
    integ = ImplicitEuler(cube, vf, 1.0, dt=0.02, fixed_nodes=_bottom(cube), solver=S(cg_tol=1e-12))
    integ.run(3)
    assert vf.steps == 3 and vf.dt == 0.02 and np.abs(vf.gammas).max() > 0


# ---------------------------------------------------------------- failures
class _Broken:
    """A force model that misbehaves on demand from a given call on."""

    def __init__(self, inner, *, after: int, what: str):
        self.inner, self.after, self.what, self.calls = inner, after, what, 0

    def force_and_stiffness(self, x):
        self.calls += 1
        f, K = self.inner.force_and_stiffness(x)
        if self.calls <= self.after:
            return f, K
        if self.what == "nan":
            return np.full_like(f, np.nan), K
        if self.what == "indefinite":
            return f, -1e6 * K
        if self.what == "inverted":
            raise mjed.InvertedElementError(np.array([7]), np.array([-0.5]))
        raise AssertionError(self.what)


@pytest.mark.parametrize(
    "what, reason",
    [("nan", "non_finite"), ("indefinite", "cg_negative_curvature"), ("inverted", "inverted")],
)
def test_failures_name_the_step_and_keep_the_last_good_state(cube, what, reason):
    model = _Broken(_field(cube), after=3, what=what)
    integ = ImplicitEuler(
        cube, model, 1.0, dt=0.01, fixed_nodes=_bottom(cube), solver=S(cg_tol=1e-12)
    )
    integ.run(3)
    good = integ.state
    with pytest.raises(mjed.IntegrationError, match="time step 4") as info:
        integ.step()
    assert info.value.reason == reason and info.value.step == 4
    if what == "inverted":
        assert info.value.cells.tolist() == [7] and "cell 7" in str(info.value)
    np.testing.assert_array_equal(integ.x, good.x)
    np.testing.assert_array_equal(integ.v, good.v)
    assert integ.t == good.t and integ.steps == 3


def test_cg_that_does_not_converge_ends_the_run(cube):
    integ = ImplicitEuler(
        cube,
        _field(cube),
        1.0,
        dt=0.01,
        fixed_nodes=_bottom(cube),
        solver=S(cg_tol=1e-14, max_iterations=2),
    )
    with pytest.raises(mjed.IntegrationError, match="max iterations after 2 iterations") as info:
        integ.step()
    assert info.value.reason == "cg_max_iterations" and integ.steps == 0
    np.testing.assert_array_equal(integ.x, cube.points)


def test_a_step_that_inverts_a_cell_is_refused(cube):
    v0 = np.zeros_like(cube.points)
    v0[:, 2] = -50.0 * cube.points[:, 2]  # crush the block into its base in one step
    history = []

    class Recorder:
        def force_and_stiffness(self, x):
            return _field(cube).force_and_stiffness(x)

        def accept_step(self, x, dt):
            history.append(dt)

    integ = ImplicitEuler(
        cube, Recorder(), 1.0, dt=0.1, gravity=None, fixed_nodes=_bottom(cube), v0=v0
    )
    with pytest.raises(
        mjed.IntegrationError, match=r"time step 1 .*inverted at the new positions"
    ) as info:
        integ.step()
    assert info.value.reason == "inverted" and len(info.value.cells) > 0
    assert history == []  # nothing was committed
    np.testing.assert_array_equal(integ.v, v0)


def test_newton_that_does_not_converge_ends_the_run(cube):
    integ = ImplicitEuler(
        cube,
        _field(cube),
        1.0,
        dt=0.05,
        fixed_nodes=_bottom(cube),
        gravity=(0, 0, -30.0),
        newton_iterations=2,
        newton_tol=1e-15,
        solver=S(cg_tol=1e-13),
    )
    with pytest.raises(mjed.IntegrationError, match="after 2 linear solves") as info:
        integ.step()
    assert info.value.reason == "newton_max_iterations"


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(dt=0.0), "dt"),
        (dict(dt=0.1, mass="diagonal"), "mass"),
        (dict(dt=0.1, rayleigh_mass=-1.0), "rayleigh_mass"),
        (dict(dt=0.1, newton_iterations=0), "newton_iterations"),
        (dict(dt=0.1, max_halvings=-1), "max_halvings"),
        (dict(dt=0.1, max_halvings=True), "max_halvings"),
        (dict(dt=0.1, gravity=(0.0, 9.81)), "gravity"),
        (dict(dt=0.1, fixed_nodes=[0, 10**6]), "fixed_nodes"),
        (
            dict(dt=0.1, fixed_nodes=[0], prescribed=([0], lambda t: np.zeros((1, 3)))),
            "both fixed and prescribed",
        ),
        (dict(dt=0.1, fixed_nodes=np.arange(27)), "every node"),
        (dict(dt=0.1, v0=np.zeros((2, 3))), "v0"),
    ],
)
def test_bad_parameters_are_refused_by_name(kwargs, word):
    mesh = mjed.TetMesh(*box_mesh(2))
    with pytest.raises(ValueError, match=word):
        ImplicitEuler(mesh, _field(mesh), 1.0, **kwargs)
    with pytest.raises(ValueError, match="empty"):
        ImplicitEuler(mesh, [], 1.0, dt=0.1)


# ---------------------------------------------------------------- linear solvers
_SOLVERS = [
    dict(preconditioner="jacobi"),
    dict(preconditioner="block-jacobi"),
    dict(preconditioner="factorized"),
    dict(solver="direct"),
]


@pytest.mark.parametrize("solver", _SOLVERS, ids=lambda s: "-".join(s.values()))
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_every_linear_solver_takes_the_same_steps(cube, solver, mass):
    """Ten steps of a hanging, damped block agree with the Jacobi CG run to the CG tolerance."""
    fixed = _bottom(cube)
    common = dict(
        dt=0.05,
        mass=mass,
        fixed_nodes=fixed,
        rayleigh_mass=0.1,
        rayleigh_stiffness=0.01,
        gravity=(3.0, 0.0, -3.0),
    )
    ref = ImplicitEuler(cube, _field(cube), 1.0, solver=S(cg_tol=1e-12), **common)
    ref.run(10)
    integ = ImplicitEuler(cube, _field(cube), 1.0, solver=S(cg_tol=1e-12, **solver), **common)
    reports = integ.run(10)
    np.testing.assert_allclose(
        integ.x, ref.x, rtol=0, atol=1e-10 * np.abs(ref.x - cube.points).max()
    )
    np.testing.assert_allclose(integ.v, ref.v, rtol=0, atol=1e-9 * np.abs(ref.v).max())
    factorizations = [r.factorizations for r in reports]
    if solver.get("solver") == "direct":
        assert factorizations == [1] * 10 and all(
            r.cg_iterations == 0 and r.cg_residual < 1e-12 for r in reports
        )
    elif solver["preconditioner"] == "factorized":
        assert factorizations[0] == 1 and sum(factorizations) < 10  # kept over several steps
        assert reports[0].cg_iterations == 1  # the exact factor of the first matrix
    else:
        assert sum(factorizations) == 0


def test_the_kept_factorisation_is_renewed_when_cg_slows_down(cube):
    fixed = _bottom(cube)
    common = dict(dt=0.05, fixed_nodes=fixed, gravity=(3.0, 0.0, -3.0))
    opts = dict(cg_tol=1e-12, preconditioner="factorized")
    # refactor_iterations=1: any solve that needs more than one iteration renews the factor.
    eager = ImplicitEuler(
        cube, _field(cube), 1.0, solver=S(refactor_iterations=1, **opts), **common
    ).run(4)
    lazy = ImplicitEuler(
        cube, _field(cube), 1.0, solver=S(refactor_iterations=1000, **opts), **common
    ).run(4)
    assert [r.factorizations for r in lazy] == [1, 0, 0, 0]
    assert sum(r.factorizations for r in eager) == 1 + sum(r.cg_iterations > 1 for r in eager[:-1])
    assert sum(r.factorizations for r in eager) > 1
    # A stale factor whose CG fails (here: a cap of one iteration) is renewed and the solve
    # repeated.
    capped = ImplicitEuler(cube, _field(cube), 1.0, solver=S(max_iterations=1, **opts), **common)
    reports = capped.run(3)
    assert [r.factorizations for r in reports] == [1, 1, 1] and capped.steps == 3


@pytest.mark.parametrize(
    "solver, reason",
    [
        (dict(solver="direct"), "not_positive_definite"),
        (
            dict(preconditioner="factorized", refactor_iterations=1),
            "not_positive_definite",
        ),  # renewed at step 3
        (
            dict(preconditioner="factorized", refactor_iterations=1000),
            "cg_negative_curvature",
        ),  # kept: CG's check
    ],
)
def test_an_indefinite_step_matrix_is_refused_with_every_solver(cube, solver, reason):
    model = _Broken(_field(cube), after=2, what="indefinite")
    # No retries: this is about what each solver itself detects (a retry renews the factor).
    integ = ImplicitEuler(
        cube,
        model,
        1.0,
        dt=0.01,
        fixed_nodes=_bottom(cube),
        solver=S(cg_tol=1e-12, **solver),
        max_halvings=0,
    )
    integ.run(2)
    good = integ.state
    with pytest.raises(
        mjed.IntegrationError, match="not positive definite|negative curvature"
    ) as info:
        integ.step()
    assert info.value.reason == reason and info.value.step == 3
    np.testing.assert_array_equal(integ.x, good.x)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(solver="lu"), "solver"),
        (dict(preconditioner="ilu"), "preconditioner"),
        (dict(refactor_iterations=0), "refactor_iterations"),
        (dict(refactor_iterations=2.5), "refactor_iterations"),
    ],
)
def test_bad_solver_options_are_refused_by_name(kwargs, word):
    with pytest.raises(ValueError, match=f"LinearSolverOptions.{word}"):
        S(**kwargs)


def test_a_direct_solve_is_held_to_the_cg_tolerance(cube):
    """A residual above cg_tol (here an unreachable tolerance) is an error, not a silent answer."""
    integ = ImplicitEuler(
        cube,
        _field(cube),
        1.0,
        dt=0.01,
        fixed_nodes=_bottom(cube),
        solver=S(cg_tol=1e-30, solver="direct"),
    )
    with pytest.raises(mjed.IntegrationError, match="relative residual") as info:
        integ.step()
    assert info.value.reason == "direct_residual" and integ.steps == 0


def test_single_precision_factors_fall_back_to_double_before_refusing(cube, monkeypatch):
    import mjed.integrator as integrator_module
    from mjed.solvers import NotPositiveDefiniteError, SPDFactor

    common = dict(dt=0.05, fixed_nodes=_bottom(cube), gravity=(3.0, 0.0, -3.0))
    double, single_precision = (
        S(cg_tol=1e-12, preconditioner="factorized", factor_precision=p)
        for p in ("double", "single")
    )
    ref = ImplicitEuler(cube, _field(cube), 1.0, solver=double, **common)
    ref.run(5)
    single = ImplicitEuler(cube, _field(cube), 1.0, solver=single_precision, **common)
    single.run(5)
    np.testing.assert_allclose(
        single.x, ref.x, rtol=0, atol=1e-10 * np.abs(ref.x - cube.points).max()
    )
    assert single._factor.dtype is np.float32

    made = []

    def no_single(A, single=False):  # as if rounding to single precision lost definiteness
        made.append(single)
        if single:
            raise NotPositiveDefiniteError(1, A.shape[0])
        return SPDFactor(A)

    monkeypatch.setattr(integrator_module, "SPDFactor", no_single)
    fallback = ImplicitEuler(cube, _field(cube), 1.0, solver=single_precision, **common)
    fallback.run(5)
    assert made[:2] == [True, False] and fallback.steps == 5
    np.testing.assert_allclose(
        fallback.x, ref.x, rtol=0, atol=1e-10 * np.abs(ref.x - cube.points).max()
    )
    with pytest.raises(ValueError, match="factor_precision"):
        S(factor_precision="half")


# ---------------------------------------------------------------- substeps, inverted cells, timing
class _FailsAbove:
    """A model that fails (an inverted cell) when the step is longer than ``limit``, or once
    it has accepted ``accepts`` steps; save/restore go to the inner model's history hooks.
    """

    def __init__(self, inner, *, limit: float, accepts: int = 10**9):
        self.inner, self.limit, self.accepts, self.accepted, self.dt = (
            inner,
            limit,
            accepts,
            0,
            None,
        )

    def prepare_step(self, dt):
        self.dt = dt
        if hasattr(self.inner, "prepare_step"):
            self.inner.prepare_step(dt)

    def force_and_stiffness(self, x):
        if self.dt > self.limit or self.accepted >= self.accepts:
            raise mjed.InvertedElementError(np.array([3]), np.array([-0.1]))
        return self.inner.force_and_stiffness(x)

    def accept_step(self, x, dt):
        self.accepted += 1
        if hasattr(self.inner, "accept_step"):
            self.inner.accept_step(x, dt)

    def save_history(self):
        return self.inner.save_history() if hasattr(self.inner, "save_history") else None

    def restore_history(self, saved):
        if saved is not None:
            self.inner.restore_history(saved)


def test_a_failed_step_is_taken_in_substeps_and_matches_the_small_steps(cube):
    opts = dict(fixed_nodes=_bottom(cube), gravity=(3.0, 0.0, -3.0), solver=S(cg_tol=1e-13))
    split = ImplicitEuler(cube, _FailsAbove(_field(cube), limit=0.015), 1.0, dt=0.04, **opts)
    report = split.step()
    # 0.04 fails, both 0.02 halves fail, the four 0.01 quarters succeed.
    assert report.substeps == 4 and report.retries == ("inverted",) * 3
    assert split.t == pytest.approx(0.04) and split.steps == 1
    small = ImplicitEuler(cube, _field(cube), 1.0, dt=0.01, **opts)
    small.run(4)
    np.testing.assert_allclose(split.x, small.x, rtol=0, atol=1e-11)
    np.testing.assert_allclose(split.v, small.v, rtol=0, atol=1e-9)


def test_a_failure_substeps_cannot_rescue_restores_everything_and_says_so(cube):
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    vf = ViscoHyperelasticForceField(cube, MATERIALS["NeoHookean"], prony=Prony((0.3,), (0.1,)))
    model = _FailsAbove(vf, limit=0.025, accepts=2)
    integ = ImplicitEuler(
        cube,
        model,
        1.0,
        dt=0.02,
        fixed_nodes=_bottom(cube),
        gravity=(3.0, 0.0, -3.0),
        solver=S(cg_tol=1e-12),
    )
    assert integ.step().substeps == 1  # one whole step: model.accepted == 1
    good, gammas, steps = integ.state, vf.gammas.copy(), vf.steps
    integ.dt = (
        0.04  # fails whole; its first half succeeds (2nd accept), the rest fails down to dt/8
    )
    with pytest.raises(
        mjed.IntegrationError, match=r"time step 2 .*retried in substeps down to dt/8"
    ) as info:
        integ.step()
    assert (
        info.value.reason == "inverted"
        and info.value.step == 2
        and info.value.time == pytest.approx(0.06)
    )
    np.testing.assert_array_equal(integ.x, good.x)
    np.testing.assert_array_equal(integ.v, good.v)
    assert integ.t == good.t and integ.steps == 1
    np.testing.assert_array_equal(vf.gammas, gammas)  # the committed half step was rolled back
    assert vf.steps == steps and model.accepted == 2


def test_no_retry_when_a_model_cannot_be_rolled_back(cube):
    class NoHooks(_FailsAbove):
        save_history = restore_history = None

    integ = ImplicitEuler(
        cube, NoHooks(_field(cube), limit=0.015), 1.0, dt=0.04, fixed_nodes=_bottom(cube)
    )
    with pytest.raises(mjed.IntegrationError) as info:
        integ.step()
    assert "retried" not in str(info.value) and info.value.time == pytest.approx(0.04)


def test_inverted_cells_are_refused_or_counted(cube):
    """allow_inverted accepts a step that inverts cells and counts them; by default it is
    refused.
    """
    v0 = np.zeros_like(cube.points)
    v0[:, 2] = -50.0 * cube.points[:, 2]  # crush the block into its base in one step
    stvk = mjed.HyperelasticForceField(
        cube, MATERIALS["StVenantKirchhoff"], regularize=True, allow_inverted=True
    )
    common = dict(
        dt=0.1,
        gravity=None,
        fixed_nodes=_bottom(cube),
        v0=v0,
        solver=S(cg_tol=1e-12),
        max_halvings=0,
    )
    with pytest.raises(mjed.IntegrationError, match="inverted"):
        ImplicitEuler(cube, stvk, 1.0, **common).step()
    integ = ImplicitEuler(cube, stvk, 1.0, allow_inverted=True, **common)
    report = integ.step()
    x = integ.x[cube.cells]
    e = x[:, 1:] - x[:, :1]
    J = np.einsum("mi,mi->m", e[:, 0], np.cross(e[:, 1], e[:, 2])) / (6.0 * cube.volumes)
    assert report.inverted_cells == int((J <= 0).sum()) > 0


def test_each_step_reports_where_its_time_went(cube):
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    vf = ViscoHyperelasticForceField(cube, MATERIALS["NeoHookean"], prony=Prony((0.3,), (0.1,)))
    integ = ImplicitEuler(cube, [vf, _field(cube)], 1.0, dt=0.02, fixed_nodes=_bottom(cube))
    times = integ.step().times
    assert len(times.models) == 2 and min(times.models) > 0 and times.system > 0 and times.solve > 0
    assert sum(times.models) + times.system + times.solve <= times.total and times.rest >= 0


def test_nodes_no_cell_uses_are_held_in_place():
    points, cells = box_mesh(2)
    points = np.vstack([points, [[5.0, 5.0, 5.0]]])  # an extra node, kept with its number
    with pytest.warns(mjed.MeshWarning, match="belong to no cell"):
        mesh = mjed.TetMesh(points, cells)
    integ = ImplicitEuler(
        mesh,
        _field(mesh),
        1.0,
        dt=0.05,
        fixed_nodes=_bottom(mesh),
        solver=S(preconditioner="factorized"),
    )
    integ.run(3)
    assert integ.idle_nodes.tolist() == [len(points) - 1]
    np.testing.assert_array_equal(integ.x[-1], [5.0, 5.0, 5.0])
    assert np.abs(integ.x[:-1] - points[:-1]).max() > 0


@pytest.mark.parametrize("name", list(MATERIALS))
def test_which_materials_may_continue_through_inverted_cells(name):
    """Only energies whose J functions stay finite at J <= 0 qualify: St Venant-Kirchhoff alone
    of the declared materials (ln J, J^(-2/3), J ln J all fail at J = 0).
    """
    from mjed.inversion import finite_when_inverted, inversion_blockers

    assert finite_when_inverted(MATERIALS[name]) == (name == "StVenantKirchhoff")
    if name != "StVenantKirchhoff":
        assert inversion_blockers(MATERIALS[name])[0][1] == "J = 0"
    field = mjed.HyperelasticForceField(
        mjed.TetMesh(*box_mesh(1)), MATERIALS[name], regularize=True, allow_inverted=True
    )
    x = field.mesh.points.copy()
    x[:, 2] *= -0.5  # every cell inverted
    with np.errstate(all="ignore"):
        f, K = field.force_and_stiffness(x)
    assert np.isfinite(f).all() == np.isfinite(K.data).all() == (name == "StVenantKirchhoff")


def test_the_fluid_pressure_is_rolled_back_with_the_step(cube):
    """A step that fails after a committed substep leaves the Darcy pressure as it was."""
    from mjed.darcy import DarcyParameters, FluidPressureForce

    fluid = FluidPressureForce(
        cube, DarcyParameters(K_lim=2200.0, kappa=1e-3), drained_nodes=_bottom(cube)
    )
    model = _FailsAbove(fluid, limit=0.025, accepts=2)
    integ = ImplicitEuler(
        cube,
        [_field(cube), model],
        1.0,
        dt=0.02,
        fixed_nodes=_bottom(cube),
        gravity=(0.0, 0.0, -30.0),
        solver=S(cg_tol=1e-12),
    )
    integ.step()
    P, J = fluid.P.copy(), fluid.J_accepted.copy()
    assert np.abs(P).max() > 0
    integ.dt = 0.04
    with pytest.raises(mjed.IntegrationError, match="retried in substeps"):
        integ.step()
    assert model.accepted == 2  # one substep was committed, then undone
    np.testing.assert_array_equal(fluid.P, P)
    np.testing.assert_array_equal(fluid.J_accepted, J)
