"""Lengths in other units (conformance.diagnosis.units): the powers of the length factor are
those of the oracle with coordinates and displacement rescaled together, and an engine that
reads its mesh so is named with its factor; a plain global factor is not taken for a unit.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from conformance.diagnosis.units import (
    ENERGY_POWER,
    FORCE_POWER,
    STIFFNESS_POWER,
    fit_derivative_scale,
    fit_length_scale,
)
from reference_fem import dolfinx_available


def test_one_factor_for_both_is_a_global_scale_not_a_unit():
    rng = np.random.default_rng(3)
    f = rng.normal(size=(4, 3))
    K = sp.csr_matrix(rng.normal(size=(12, 12)))
    assert fit_length_scale(f, K, 0.25 * f, 0.25 * K) is None
    assert fit_length_scale(f, K, 1e-6 * f, 1e-4 * K) is None  # 1e-6 is not (1e-4)^2
    found = fit_length_scale(f, K, 1e-6 * f, 1e-3 * K)
    assert found is not None and abs(found.s - 1e-3) < 1e-12
    assert np.allclose(found.force, f) and abs(found.stiffness - K).max() < 1e-12
    assert fit_length_scale(0 * f, K, 0 * f, 1e-3 * K) is None  # no force: no second scaling


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_powers_are_those_of_the_oracle_on_a_rescaled_mesh():
    from common.cases import default_material
    from meshes import unit_cube
    from reference_fem import UFLOracle

    points, cells = unit_cube(75)[:2]
    rng = np.random.default_rng(0)
    x = points + 0.02 * rng.normal(size=points.shape) * np.ptp(points)
    model = default_material("MooneyRivlin")
    base = UFLOracle(points, cells, model)
    f, K = base.force_and_stiffness(x)
    for s in (1e-3, 25.4e-3):
        o = UFLOracle(s * points, cells, model)
        fs, Ks = o.force_and_stiffness(s * x)
        assert np.allclose(fs, s**FORCE_POWER * f, rtol=1e-9, atol=1e-12 * np.abs(fs).max())
        assert abs(Ks - s**STIFFNESS_POWER * K).max() <= 1e-9 * abs(Ks).max()
        assert o.energy(s * x) == pytest.approx(s**ENERGY_POWER * base.energy(x), rel=1e-9)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize("s", [1e-3, 1e3])
def test_an_engine_reading_its_mesh_in_other_units_is_named(s):
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(case):  # every length times s, the moduli as given
        o = UFLOracle(s * case.points, case.cells, case.model)
        return o.force_and_stiffness(s * case.positions)

    run = check_implementation(engine, material="NeoHookean", states=("random",), probes=False)
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
    assert named[0].code == "length-units", outcome.diagnosis.text()
    assert named[0].figures["s"] == pytest.approx(s, rel=1e-9)


def test_ratios_near_the_float_limit_name_nothing_and_do_not_overflow():
    f = np.ones((4, 3))
    K = sp.identity(12, format="csr")
    assert fit_length_scale(f, K, 1e300 * f, 1e300 * K) is None
    assert fit_length_scale(f, K, 1e-300 * f, 1e200 * K) is None


def test_derivatives_per_another_unit_scale_the_force_by_t_and_the_stiffness_by_t_squared():
    """The other way round from a mesh in other units (force s^2, stiffness s): a derivative
    taken per 1e-3 of the length scales the force by 1e-3 and the stiffness by 1e-6.
    """
    rng = np.random.default_rng(4)
    f = rng.normal(size=(4, 3))
    K = sp.csr_matrix(rng.normal(size=(12, 12)))
    found = fit_derivative_scale(f, K, 1e-3 * f, 1e-6 * K)
    assert found is not None and abs(found.t - 1e-3) < 1e-15
    assert np.allclose(found.force, f) and abs(found.stiffness - K).max() < 1e-12
    assert "1e-06" in found.words() and "1000" in found.words()
    assert fit_derivative_scale(f, K, 1e-6 * f, 1e-3 * K) is None  # a mesh in other units
    assert fit_derivative_scale(f, K, 0.25 * f, 0.25 * K) is None  # one global factor
    assert fit_derivative_scale(0 * f, K, 0 * f, 1e-6 * K) is None  # no force, no t


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_engine_differentiating_per_millimetre_is_named_and_a_wrong_energy_denies_it():
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(wrong_energy: bool):
        def run(case):  # derivatives per 1e-3 of the kit's length, the energy as it is
            o = UFLOracle(case.points, case.cells, case.model)
            f, K = o.force_and_stiffness(case.positions)
            W = o.energy(case.positions) * (2.0 if wrong_energy else 1.0)
            return 1e-3 * f, 1e-6 * K, W

        return run

    for wrong, code in ((False, "derivative-units"), (True, None)):
        run = check_implementation(
            engine(wrong), material="NeoHookean", states=("random",), probes=False
        )
        (outcome,) = run.outcomes
        codes = [c.code for c in outcome.diagnosis.causes]
        assert outcome.status == "failed", outcome.diagnosis.text()
        if code:
            assert codes == [code], outcome.diagnosis.text()
            assert outcome.diagnosis.causes[0].figures["t"] == pytest.approx(1e-3, rel=1e-9)
        else:
            assert "derivative-units" not in codes, outcome.diagnosis.text()
