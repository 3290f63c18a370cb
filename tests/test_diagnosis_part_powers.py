"""One part of the energy multiplied per cell by a power of J (conformance.diagnosis.part_powers):
a Mooney-Rivlin engine whose c1 part is J^(-1/3) times the right one in every cell (its
isochoric J^(-2/3) typed J ** (-2 // 3), the chain rule's coefficients kept), built here as MJED's
element arrays with that part scaled per cell; against it, factors that are not one power of J
(a constant, a power with noise, the stiffness alone), a homogeneous state, and the kit-level
step that gives a homogeneous case the cause (corroborate).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from conformance.diagnosis.corroborate import _power_covered
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import Finding
from conformance.diagnosis.part_powers import exponent_text, part_power_findings
from conformance.diagnosis.part_scalars import parameter_parts
from conformance.judge.compare import DOUBLE
from mjed import materials as M


class _Out:
    def __init__(self, force, stiffness):
        self.force, self.stiffness = force, stiffness


def _case(stretch, noise):
    points, cells = box_mesh(3, jitter=0.2, seed=5)
    rng = np.random.default_rng(5)
    x = points @ np.diag(stretch).T + noise * rng.standard_normal(points.shape)
    model = M.MooneyRivlin(c1=1200.0, c2=300.0, k0=2e4)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    parts = parameter_parts(model, points, cells, x, split)
    return points, cells, x, model, split, f_o, K_o, s, parts


@pytest.fixture(scope="module")
def case():
    return _case([1.2, 0.9, 0.95], 0.05)


def _engine(case, lam, *, force=True, part="c1"):
    """The oracle plus lam (m,) times the part in ``part``, per cell (force too unless not
    ``force``).
    """
    _, cells, _, _, split, f_o, K_o, _, parts = case
    fe, Ke = parts[part]
    df, dK = assemble(cells, split.n, lam[:, None, None] * fe, lam[:, None, None] * Ke)
    return _Out(f_o + df if force else f_o, K_o + dK)


def _read(case, out):
    points, cells, x, model, split, f_o, K_o, s, _ = case
    return part_power_findings(split, model, points, x, out, f_o, K_o, s, DOUBLE)


def _j(case):
    return np.linalg.det(case[4].F)


def test_floor_division_of_the_isochoric_exponent_is_named_with_its_power(case):
    J = _j(case)
    assert np.ptp(np.log(J)) > 0.05
    found = _read(case, _engine(case, J ** (-1.0 / 3.0) - 1.0))
    assert [f.code for f in found] == ["part-power-of-j"], found
    f = found[0]
    assert f.figures["parameter"] == "c1"
    assert abs(f.figures["exponent"] + 1.0 / 3.0) < 1e-9
    assert "J^(-1/3)" in f.title and "-2 // 3" in f.title and "c1 (I1b - 3)" in f.title


def test_another_power_is_named_without_the_floor_division_example(case):
    found = _read(case, _engine(case, _j(case) ** (2.0 / 3.0) - 1.0, part="c2"))
    assert [f.figures["parameter"] for f in found] == ["c2"]
    assert "J^(2/3)" in found[0].title and "//" not in found[0].title


def test_factors_that_are_not_one_power_of_j_are_not_named(case):
    J = _j(case)
    m = J.size
    constant = np.full(m, 0.08)  # a coefficient: no power of J fits every cell
    assert _read(case, _engine(case, constant)) == []
    rng = np.random.default_rng(1)
    noisy = J ** (-1.0 / 3.0) * (1.0 + 1e-3 * rng.standard_normal(m)) - 1.0
    assert _read(case, _engine(case, noisy)) == []
    # the factor on the stiffness alone: the force does not follow it
    assert _read(case, _engine(case, J ** (-1.0 / 3.0) - 1.0, force=False)) == []


def test_a_state_of_one_j_reads_no_exponent():
    uniaxial = _case([1.3, 1.0, 1.0], 0.0)
    J = _j(uniaxial)
    assert np.ptp(J) < 1e-9
    assert _read(uniaxial, _engine(uniaxial, J ** (-1.0 / 3.0) - 1.0)) == []


def test_the_one_j_state_is_covered_by_the_power_at_its_j():
    cause = Finding(
        "part-power-of-j",
        "c1 x J^(-1/3)",
        "explains",
        "",
        {"parameter": "c1", "exponent": -1.0 / 3.0, "covers": ["term-coefficients"]},
    )

    def refit(coefficients, J=1.3):
        figs = {"terms": [["c2"], ["c1"], ["k0"]], "coefficients": coefficients}
        if J is not None:
            figs["one_j"] = J
        return Finding("term-coefficients", "refit", "explains", "", figs)

    k = 1.3 ** (-1.0 / 3.0)
    assert _power_covered(refit([1.0, k, 1.0]), cause)
    assert not _power_covered(refit([1.0, 0.9, 1.0]), cause)  # another factor
    assert not _power_covered(refit([1.01, k, 1.0]), cause)  # another term off too
    assert not _power_covered(refit([1.0, k, 1.0], J=None), cause)  # J varies there


def test_exponents_print_as_small_fractions():
    assert exponent_text(-1.0 / 3.0) == "-1/3"
    assert exponent_text(2.0 / 3.0) == "2/3"
    assert exponent_text(0.123456789) == "0.123457"
