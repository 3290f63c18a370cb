"""One part of the energy off by a factor per cell drawn at random (conformance.diagnosis.
part_scalars): a Demiray engine whose exponential's argument b (I1b - 3) is held in float32, the
rest in double, built here as MJED's element arrays with the part proportional to a scaled per
cell by exactly the factor that rounding gives; against it, the per-cell factors a double
engine's mistakes give (one constant, a smooth function of the state) and a factor on the
stiffness alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble
from conformance.diagnosis.part_scalars import (
    UNIT_ROUNDOFF,
    explained_share,
    parameter_parts,
    part_scalar_findings,
)
from conformance.judge.compare import DOUBLE
from mjed import materials as M


class _Out:
    def __init__(self, force, stiffness):
        self.force, self.stiffness = force, stiffness


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(3, jitter=0.2, seed=3)
    rng = np.random.default_rng(3)
    x = points @ np.diag([1.15, 0.93, 0.95]).T + 0.04 * rng.standard_normal(points.shape)
    model = M.Demiray(a=3000.0, b=2.5, k0=8e4)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    parts = parameter_parts(model, points, cells, x, split)
    return points, cells, x, model, split, f_o, K_o, s, parts


def _i1b(F):
    J = np.linalg.det(F)
    return J ** (-2.0 / 3.0) * np.einsum("mij,mij->m", F, F)


def _engine(case, lam, *, force=True):
    """The oracle plus lam (m,) times the part in a, per cell (force too unless not ``force``)."""
    _, cells, _, _, split, f_o, K_o, _, parts = case
    fe, Ke = parts["a"]
    df, dK = assemble(cells, split.n, lam[:, None, None] * fe, lam[:, None, None] * Ke)
    return _Out(f_o + df if force else f_o, K_o + dK)


def _rounded_argument(case):
    """The factor exp(fl32(x)) / exp(x) - 1 of each cell, x = b (I1b - 3)."""
    split, model = case[4], case[3]
    arg = model.b * (_i1b(split.F) - 3.0)
    return np.expm1(arg.astype(np.float32).astype(float) - arg)


def _read(case, out, noisy=True):
    points, cells, x, model, split, f_o, K_o, s, _ = case
    return part_scalar_findings(split, model, points, x, out, f_o, K_o, s, DOUBLE, noisy)


def test_the_linear_parameters_parts_are_read_off_and_sum_to_the_oracle(case):
    _, cells, _, _, split, f_o, K_o, _, parts = case
    assert set(parts) == {"a", "k0"}  # b enters the exponential: not linear
    fe = parts["a"][0] + parts["k0"][0]
    Ke = parts["a"][1] + parts["k0"][1]
    f, K = assemble(cells, split.n, fe, Ke)
    assert np.linalg.norm(f - f_o) <= 1e-9 * np.linalg.norm(f_o)
    assert abs(K - K_o).max() <= 1e-9 * abs(K_o).max()


def test_an_exponential_argument_in_float32_is_named_on_its_part(case):
    lam = _rounded_argument(case)
    assert 0 < np.sqrt(np.mean(lam**2)) < 10 * UNIT_ROUNDOFF
    for noisy in (True, None):  # with probes (drawn anew) or over many distinct cells
        found = _read(case, _engine(case, lam), noisy)
        assert [f.code for f in found] == ["single-precision-part-scalar"], found
        assert found[0].figures["parameter"] == "a"
        assert found[0].figures["explained_share"] < 0.3
        assert "float32" in found[0].title and " a " in found[0].title


def test_smooth_or_constant_factors_are_not_rounding(case):
    split = case[4]
    i1b = _i1b(split.F)
    smooth = 1e-7 * (i1b - i1b.mean()) / np.std(i1b)  # a state-dependent formula error
    assert explained_share(split.F, smooth) > 0.99
    assert _read(case, _engine(case, smooth)) == []
    constant = np.full(split.cells.shape[0], 1e-7)  # a rounded constant: one factor everywhere
    assert _read(case, _engine(case, constant)) == []


def test_a_factor_on_the_stiffness_alone_or_a_steady_error_is_not_named(case):
    lam = _rounded_argument(case)
    assert _read(case, _engine(case, lam, force=False)) == []
    # the same numbers, but the probes saw an error that does not change (not drawn anew)
    assert _read(case, _engine(case, lam), noisy=False) == []


def test_factors_beyond_float32s_size_are_not_named(case):
    lam = 1e4 * _rounded_argument(case)  # random per cell, but 1e-3: cells mis-weighted
    assert _read(case, _engine(case, lam)) == []


def test_a_constant_beside_the_rounding_is_not_named(case):
    lam = _rounded_argument(case)
    shifted = lam + 0.7 * np.sqrt(np.mean(lam**2))  # rounding plus a systematic factor
    assert 0.1 < np.mean(shifted > 0) < 0.9  # the sign test alone would let it through
    assert _read(case, _engine(case, shifted)) == []
