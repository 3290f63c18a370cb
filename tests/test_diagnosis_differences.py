"""A tangent from differences of each element's force (conformance.diagnosis.differences): the
scheme and the per-cell step rule fitted, and a step so small that round-off dominates named
only on its noise signature. The mistaken engines are built here from MJED's element forces;
MJED stands in for the oracle in the fast tests, and one test runs the whole check.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh

from common.cases import default_material
from conformance.diagnosis.differences import (
    cell_column_derivatives,
    fit_element_differences,
    roundoff_dominated,
)
from conformance.diagnosis.elements import assemble, element_split
from conformance.judge.compare import DOUBLE, scales
from reference_fem import dolfinx_available


def _state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    x = x + 0.02 * np.random.default_rng(seed).standard_normal(points.shape)
    return points, cells, x


def _difference_engine(model, points, cells, x, step, central):
    """(f, K) with K differences of each element's force; step: (m,) per cell."""
    import mjed

    m = cells.shape[0]
    loose = np.arange(4 * m).reshape(m, 4)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points[cells].reshape(-1, 3), loose), model)
    xs = x[cells].reshape(-1, 3)
    fe = field.element_forces(xs)
    Ke = np.empty((m, 12, 12))
    for j in range(12):
        b, c = divmod(j, 3)
        xp, xm = xs.copy(), xs.copy()
        xp[loose[:, b], c] += step
        xm[loose[:, b], c] -= step
        if central:
            d = (field.element_forces(xp) - field.element_forces(xm)) / (2 * step[:, None, None])
        else:
            d = (field.element_forces(xp) - fe) / step[:, None, None]
        Ke[:, :, j] = -d.reshape(m, 12)
    return assemble(cells, points.shape[0], fe, Ke)


def _oracle(model, points, cells, x):
    import mjed

    f_o, K_o = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model).force_and_stiffness(
        x
    )
    K_o = sp.csr_matrix(K_o)
    s = scales(0.5, 1.0, f_o, K_o)
    split = element_split(model, points, cells, x, f_o, K_o, s, DOUBLE)
    assert split is not None
    return split, f_o, K_o


def test_central_differences_with_a_step_per_cell_are_fitted():
    model = default_material("MooneyRivlin")
    points, cells, x = _state()
    e = points[cells][:, :, None, :] - points[cells][:, None, :, :]
    longest = np.sqrt((e**2).sum(-1)).max(axis=(1, 2))
    f, K = _difference_engine(model, points, cells, x, 1e-4 * longest, central=True)
    split, f_o, K_o = _oracle(model, points, cells, x)
    d = cell_column_derivatives(model, points, cells, x)
    fit = fit_element_differences(split, d, (K - K_o).tocsr(), K_o)
    assert fit.scheme == "central" and fit.rule == "longest edge", fit
    assert fit.explained > 0.99 and abs(fit.step / 1e-4 - 1) < 1e-3, fit
    assert "longest edge" in fit.words()


def test_forward_differences_with_one_step_are_fitted_and_not_called_roundoff():
    model = default_material("NeoHookean")
    points, cells, x = _state(1)
    f, K = _difference_engine(model, points, cells, x, np.full(len(cells), 1e-5), central=False)
    split, f_o, K_o = _oracle(model, points, cells, x)
    d = cell_column_derivatives(model, points, cells, x)
    fit = fit_element_differences(split, d, (K - K_o).tocsr(), K_o)
    assert fit.scheme == "forward" and fit.rule == "absolute" and fit.explained > 0.99, fit
    assert abs(fit.step / 1e-5 - 1) < 1e-2
    assert not roundoff_dominated(split, K, K_o).holds


def test_a_tiny_step_has_the_roundoff_signature_and_a_formula_error_has_not():
    model = default_material("NeoHookean")
    points, cells, x = _state(2)
    f, K = _difference_engine(model, points, cells, x, np.full(len(cells), 1e-11), central=False)
    split, f_o, K_o = _oracle(model, points, cells, x)
    r = roundoff_dominated(split, K, K_o)
    assert r.holds, r
    # a systematic error (a part of K scaled), and float32 storage: neither is that noise
    assert not roundoff_dominated(split, (K_o * (1 + 1e-7)).tocsr(), K_o).holds
    K32 = sp.csr_matrix(K_o.astype(np.float32), dtype=np.float64)
    assert not roundoff_dominated(split, K32, K_o).holds


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_check_names_a_per_cell_step():
    from conformance.protocol import check_implementation

    points, cells = box_mesh(2, jitter=0.2, seed=4)

    def engine(case):
        e = case.points[case.cells][:, :, None, :] - case.points[case.cells][:, None, :, :]
        step = 1e-4 * np.sqrt((e**2).sum(-1)).max(axis=(1, 2))
        return _difference_engine(
            case.model, case.points, case.cells, case.positions, step, central=True
        )

    run = check_implementation(
        engine, material="NeoHookean", mesh=(points, cells), states=("random",)
    )
    for o in run.outcomes:
        first = o.diagnosis.findings[0]
        assert first.code == "finite-difference", o.diagnosis.text()
        assert first.figures["rule"] == "longest edge", o.diagnosis.text()


def test_a_complex_step_too_large_is_fitted_as_a_complex_step():
    """A complex step's tangent, Im f(x + i h e_j) / h, errs by - h^2/6 f''' where central
    differences err by + h^2/6 f''': to that order it is 2 K - K_central(h). Its fit has the
    central scheme's basis with a negative coefficient, and is named a complex step.
    """
    model = default_material("Demiray")
    points, cells, x = _state(3)
    split, f_o, K_o = _oracle(model, points, cells, x)
    h = np.full(len(cells), 2e-3)
    _, K_central = _difference_engine(model, points, cells, x, h, central=True)
    K = (2 * K_o - K_central).tocsr()
    d = cell_column_derivatives(model, points, cells, x)
    fit = fit_element_differences(split, d, (K - K_o).tocsr(), K_o)
    assert fit.scheme == "complex step" and fit.rule == "absolute", fit
    assert fit.explained > 0.99 and abs(fit.step / 2e-3 - 1) < 1e-2, fit
    assert "complex step" in fit.words() and "too large" in fit.words()
