"""The curvature of the isochoric factor J^p written wrongly in the tangent
(conformance.diagnosis.isochoric_curvature).

The engines differentiate their energy with hyper-dual numbers (tests/hyperdual_engine.py), the
power J^p of I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2 through a rule of their own whose second
derivative is written as the mistake says; MJED stands in for the oracle.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import box_mesh, mjed_split
from hyperdual_engine import density_engine

from common.cases import default_material
from conformance.diagnosis.isochoric_curvature import isochoric_curvature_findings
from conformance.judge.compare import DOUBLE


def _power(curvature):
    """x^p with its second derivative curvature(p) x^(p - 2) (right: p (p - 1))."""

    def power(x, p):
        return x.apply(x.a**p, p * x.a ** (p - 1.0), curvature(p) * x.a ** (p - 2.0))

    return power


def _mooney_rivlin(power):
    def density(model, k, F, R):
        I1b = power(k.J, -2.0 / 3.0) * k.I1
        I2b = power(k.J, -4.0 / 3.0) * k.I2
        return model.c1 * (I1b - 3.0) + model.c2 * (I2b - 3.0) + model.k0 / 2.0 * k.lnJ * k.lnJ

    return density_engine(density)


def _yeoh(power):
    def density(model, k, F, R):
        u = power(k.J, -2.0 / 3.0) * k.I1 - 3.0
        W = model.c10 * u + model.c20 * u * u + model.c30 * u * u * u
        return W + model.k0 / 2.0 * k.lnJ * k.lnJ

    return density_engine(density)


def _run(name, engine, seed=4, stretch=(1.1, 0.95, 0.92), noise=0.03):
    model = default_material(name)
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag(stretch).T + noise * rng.standard_normal(points.shape)
    _, f_o, K_o, s = mjed_split(model, points, cells, x)
    f, K, _ = engine(SimpleNamespace(points=points, cells=cells, positions=x, model=model))
    f = f.reshape(-1, 3)
    return isochoric_curvature_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE)


RIGHT = _power(lambda p: p * (p - 1.0))


@pytest.mark.parametrize("name, make", [("MooneyRivlin", _mooney_rivlin), ("Yeoh", _yeoh)])
def test_the_right_rule_is_not_named(name, make):
    assert _run(name, make(RIGHT)) == []


@pytest.mark.parametrize(
    "slip, curvature",
    [
        ("p-squared", lambda p: p * p),
        ("sign", lambda p: -p * (p - 1.0)),
        ("dropped", lambda p: 0.0),
    ],
)
def test_a_power_rule_with_the_wrong_curvature_is_named(slip, curvature):
    found = _run("MooneyRivlin", _mooney_rivlin(_power(curvature)))
    assert [x.code for x in found] == [f"isochoric-curvature-{slip}"], [x.title for x in found]
    assert "I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2" in found[0].title


def test_a_slip_in_one_factor_only_is_not_named_as_the_rule():
    # the rule right for J^(-2/3), p^2 for J^(-4/3): not one rule written once, and no slip of
    # SLIPS predicts that combination
    def curvature_of(p):
        return p * p if p < -1.0 else p * (p - 1.0)

    assert _run("MooneyRivlin", _mooney_rivlin(_power(curvature_of))) == []


def test_a_homogeneous_stretch_names_the_slip_with_one_isochoric_term():
    found = _run("Yeoh", _yeoh(_power(lambda p: p * p)), noise=0.0)
    assert [x.code for x in found] == ["isochoric-curvature-p-squared"]
