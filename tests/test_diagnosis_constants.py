"""A constant of the formula with another value (issue 29): the exponents of J refitted through
the oracle.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
import scipy.sparse as sp

from conformance.diagnosis.constants import describe_exponent, fit_exponents
from conformance.diagnosis.refit import Target
from mjed.materials import MooneyRivlin, Ogden
from reference_fem import dolfinx_available

needs_oracle = pytest.mark.skipif(
    not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
)


def test_the_exponents_are_read_from_the_declared_formula():
    pytest.importorskip("ufl")
    from conformance.diagnosis.energy_terms import j_exponents

    keys = dict(j_exponents(MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4)))
    assert sorted(keys.values()) == pytest.approx([-4 / 3, -2 / 3])
    ((key, value),) = j_exponents(Ogden(mu=5000.0, alpha=3.0, k0=3e4))
    assert "alpha" in key and value == pytest.approx(-1.0)  # J^(-alpha/3), a parameter in it


def test_an_exponent_in_words():
    assert (
        describe_exponent("-0.6666666666666666", -2 / 3, -0.66667)
        == "J^(-2/3) of the formula is J^(-0.66667) in your engine"
    )
    assert (
        describe_exponent("-1 * alpha / 3.0", -1.0, -2 / 3)
        == "J^(-alpha/3) = J^(-1) of the formula is J^(-2/3) in your engine"
    )


def test_two_exponents_fitted_together_and_only_the_changed_one_named():
    """A stand-in for the oracle: f_i = J_i^p1 + 2 J_i^p2 over a few J; the engine has p1 off."""
    J = np.linspace(0.7, 1.4, 9)

    def evaluate(factors):
        (_, r1), (_, r2) = factors
        f = J ** (r1 * -2 / 3) + 2 * J ** (r2 * -4 / 3)
        return np.tile(f, (3, 1)).T, sp.diags(f).tocsr()

    exps = [("-0.6666666666666666", -2 / 3), ("-1.3333333333333333", -4 / 3)]
    f, K = evaluate((("a", -0.66667 / (-2 / 3)), ("b", 1.0)))
    found = fit_exponents(exps, evaluate, Target(f, K, 1.0, 1.0, 1e-10, 1e-10))
    assert found is not None and found.fit.agrees
    ((key, declared, engine),) = found.changed()
    assert key == exps[0][0] and engine == pytest.approx(-0.66667, rel=1e-9)


@pytest.fixture(scope="module")
def check():
    from conformance.protocol import check_implementation

    logging.disable(logging.INFO)

    def run(engine, material):
        return check_implementation(
            engine, material=material, mesh="cube-small", states=("random",), probes=False
        )

    return run


@pytest.mark.oracle
@needs_oracle
def test_ogden_with_another_power_of_j_is_named_with_it(check):
    """MJED's Ogden terms with J^(-2/3) for J^(-alpha/3) (alpha = 3): named with the power."""
    import mjed
    from mjed.materials.base import Material
    from mjed.spectral import EigenPowerSum
    from mjed.terms import JPower, LogPolynomial, Term, TermGroup, Unity

    class OgdenPower(Material):
        def __init__(self, m):
            self.m = m

        def decomposition(self):
            c = self.m.mu / self.m.alpha**2
            return (
                TermGroup(
                    (
                        Term(JPower(-2.0 / 3.0), EigenPowerSum(c, self.m.alpha / 2.0)),
                        Term(LogPolynomial(0.5 * self.m.k0, 0.0, -3.0 * c), Unity()),
                    )
                ),
            )

    def engine(case):
        field = mjed.HyperelasticForceField(
            mjed.TetMesh(case.points, case.cells), OgdenPower(case.model)
        )
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    (outcome,) = check(engine, Ogden(mu=5000.0, alpha=3.0, k0=3e4)).outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and d.causes, d.text()
    assert d.causes[0].code == "formula-constant", d.text()
    assert "J^(-alpha/3) = J^(-1) of the formula is J^(-2/3) in your engine" in d.causes[0].title
