"""The porous volumetric term: the substitution, its derivatives, and the UFL oracle."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh

import mjed
from comparisons.equivalence.taylor import energy_force_rates, force_stiffness_rates
from mjed.materials import ArrudaBoyce, MooneyRivlin, NeoHookean, StVenantKirchhoff
from mjed.porous import PorousVolume, with_porous_volume

LIVER = PorousVolume(f_w=0.5, K0=400.0, K_lim=2200.0)  # the paper's Fig. 1 (right)


def _graded_state(X):
    """A smooth state whose cells span J ~ 0.5 .. 1.3, i.e. both sides of J0 = 0.68."""
    rng = np.random.default_rng(1)
    x = X.copy()
    x[:, 0] *= 0.6 + 0.5 * X[:, 1]
    return x + 0.02 * rng.standard_normal(X.shape)


@pytest.mark.parametrize("tangent", ["paper", "slope"])
def test_substituted_stress_is_continuous_with_continuous_slope_at_J0(tangent):
    law = PorousVolume(0.5, 400.0, 2200.0, tangent=tangent)
    J0, eps = law.J0, 1e-7
    U, s, k = law(np.array([J0 - eps, J0 + eps]))
    # Across J0 the stress moves by slope * 2 eps and no more (a jump would add O(1)).
    assert abs(s[1] - s[0] - 2 * eps * law.tangent_slope) < 1e-3 * eps * law.tangent_slope
    assert abs(k[1] - k[0]) < 1e-4 * law.tangent_slope
    # Above J0 the stress is Hencky's; below, it is the tangent line (linear: second difference 0).
    J = np.linspace(J0 + 0.01, 1.4, 7)
    assert np.allclose(law.stress(J), law.hencky_stress(J), rtol=1e-13)
    Jb = np.linspace(-0.5, J0, 5)
    assert np.allclose(np.diff(law.stress(Jb), 2), 0.0, atol=1e-9)
    # Below J0 the substituted stress is finite where Hencky's is infinite.
    assert np.isfinite(law.stress(1 - law.f_w)) and not np.isfinite(law.hencky_stress(1 - law.f_w))


def test_J0_formula_and_the_slope_there():
    paper = PorousVolume(0.5, 400.0, 2200.0)
    slope = PorousVolume(0.5, 400.0, 2200.0, tangent="slope")
    assert paper.J0 == pytest.approx(1 - 0.5 + 400 / 2200)
    # At the paper's J0 the slope is f_w K_lim, not K_lim; "slope" puts J0 where it is K_lim.
    assert paper.tangent_slope == pytest.approx(0.5 * 2200.0)
    assert slope.tangent_slope == pytest.approx(2200.0)


def test_energy_derivatives_are_the_stress_and_its_slope():
    J = np.array([0.2, 0.6, 0.75, 0.9, 1.0, 1.2, 1.6])
    h = 1e-6
    U, s, k = LIVER(J)
    assert np.allclose((LIVER(J + h)[0] - LIVER(J - h)[0]) / (2 * h), s, rtol=1e-7, atol=1e-6)
    assert np.allclose((LIVER(J + h)[1] - LIVER(J - h)[1]) / (2 * h), k, rtol=1e-6)
    assert LIVER(np.array([1.0]))[0][0] == 0.0 and LIVER(np.array([1.0]))[1][0] == 0.0
    # Compression gives a negative (compressive) Cauchy stress, extension a positive one.
    assert s[0] < 0 < s[-1]


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(f_w=0.0, K0=1.0, K_lim=2.0), "f_w"),
        (dict(f_w=1.2, K0=1.0, K_lim=2.0), "f_w"),
        (dict(f_w=0.5, K0=-1.0, K_lim=2.0), "K0"),
        (dict(f_w=0.5, K0=1.0, K_lim=float("nan")), "K_lim"),
        (dict(f_w=0.5, K0=1.0, K_lim=1.0), "J0"),  # K0/K_lim >= f_w: J0 >= 1
        (dict(f_w=0.5, K0=1.0, K_lim=4.0, tangent="secant"), "tangent"),
    ],
)
def test_invalid_parameters_are_named(kwargs, name):
    with pytest.raises(ValueError, match=name):
        PorousVolume(**kwargs)


def test_replace_mode_refusals():
    with pytest.raises(ValueError, match="non-zero slope"):
        with_porous_volume(NeoHookean(mu=1.0, lam=2.0), LIVER, mode="replace")
    with pytest.raises(ValueError, match="no J-only"):
        with_porous_volume(StVenantKirchhoff(mu=1.0, lam=2.0), LIVER, mode="replace")
    with pytest.raises(ValueError, match="mode"):
        with_porous_volume(NeoHookean(mu=1.0, lam=2.0), LIVER, mode="both")


@pytest.mark.parametrize("mode", ["add", "replace"])
def test_rest_is_stress_free_and_taylor_rates(mode):
    X, T = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(X, T)
    field = mjed.HyperelasticForceField(
        mesh, with_porous_volume(ArrudaBoyce(mu=770.0, k0=7500.0), LIVER, mode=mode)
    )
    assert np.abs(field.force(X)).max() < 1e-9
    assert abs(field.energy(X)) < 1e-9
    x = _graded_state(X)
    v = np.random.default_rng(3).standard_normal(X.shape)
    assert energy_force_rates(field, x, v, 1e-3).min() >= 1.9
    assert force_stiffness_rates(field, x, v, 1e-3).min() >= 1.9


def test_replace_drops_only_the_bulk_term():
    X, T = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(X, T)
    x = _graded_state(X)
    base = MooneyRivlin(c1=300.0, c2=100.0, k0=5000.0)
    replaced = mjed.HyperelasticForceField(mesh, with_porous_volume(base, LIVER, mode="replace"))
    added = mjed.HyperelasticForceField(mesh, with_porous_volume(base, LIVER))
    no_bulk = mjed.HyperelasticForceField(mesh, MooneyRivlin(c1=300.0, c2=100.0, k0=1e-300))
    full = mjed.HyperelasticForceField(mesh, base)
    # add - replace = the base's bulk energy = full - (base without bulk)
    assert np.isclose(
        added.energy(x) - replaced.energy(x), full.energy(x) - no_bulk.energy(x), rtol=1e-12
    )


@pytest.mark.oracle
@pytest.mark.parametrize("mode", ["add", "replace"])
@pytest.mark.parametrize("tangent", ["paper", "slope"])
def test_porous_force_and_stiffness_match_the_ufl_oracle(mode, tangent):
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx")
    from reference_fem.porous_energy import PorousOracle

    law = PorousVolume(0.5, 400.0, 2200.0, tangent=tangent)
    X, T = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(X, T)
    base = ArrudaBoyce(mu=770.0, k0=7500.0)
    field = mjed.HyperelasticForceField(mesh, with_porous_volume(base, law, mode=mode))
    oracle = PorousOracle(X, T, porous=law, base=base, mode=mode)
    x = _graded_state(X)
    J = np.linalg.det(np.einsum("mai,maj->mij", x[T], mesh.D))
    assert (J < law.J0).any() and (J > law.J0).any()  # both branches are exercised
    f, K = field.force_and_stiffness(x)
    f_o, K_o = oracle.force_and_stiffness(x)
    assert np.linalg.norm(f - f_o) <= 1e-10 * np.linalg.norm(f_o)
    assert np.linalg.norm((K - K_o).toarray()) <= 1e-10 * np.linalg.norm(K_o.toarray())
    assert np.isclose(field.energy(x), oracle.energy(x), rtol=1e-12)
    # Not vacuous: a 1e-6 change of K0 is visible at this tolerance.
    shifted = PorousOracle(
        X,
        T,
        porous=PorousVolume(0.5, 400.0 * (1 + 1e-6), 2200.0, tangent=tangent),
        base=base,
        mode=mode,
    )
    assert np.linalg.norm(f - shifted.force_and_stiffness(x)[0]) > 1e-10 * np.linalg.norm(f_o)


def test_pressure_model_at_zero_pressure_carries_exactly_the_porous_solid():
    """FluidPressureForce(solid=...) at P = 0 is the porous solid alone: the coupling keeps the
    solid's term and adds nothing else (the independent check of both is the UFL oracle).
    """
    from mjed.darcy import DarcyParameters, FluidPressureForce
    from mjed.porous import PorousSolid

    X, T = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(X, T)
    x = _graded_state(X)
    f, K = mjed.HyperelasticForceField(mesh, PorousSolid(LIVER)).force_and_stiffness(x)
    f_d, K_d = FluidPressureForce(
        mesh, DarcyParameters(2200.0, 1e-3), solid=LIVER
    ).force_and_stiffness(x)
    assert np.linalg.norm(f - f_d) <= 1e-12 * np.linalg.norm(f)
    assert abs(K - K_d).max() <= 1e-12 * abs(K).max()
    with pytest.raises(ValueError, match="porous"):
        PorousSolid(0.5)
