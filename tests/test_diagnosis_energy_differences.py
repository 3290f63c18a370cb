"""The stress by differences of the energy density (conformance.diagnosis.energy_differences):
the mistaken engine differences MJED's per-cell energy with its own step and scheme and
assembles its own forces; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

import mjed
from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.energy_differences import fit_energy_differences
from conformance.diagnosis.strain_differences import VOIGT
from mjed.evaluation import Want


def _case(material, seed):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    x = x + 0.02 * np.random.default_rng(seed).standard_normal(points.shape)
    model = default_material(material)
    return model, points, x, *mjed_split(model, points, cells, x)


def _energy_density(model, points, split, F2):
    """(m,) W of each cell at F2 (m, 3, 3), the cells pulled apart and moved to F2."""
    m = split.F.shape[0]
    X = points[split.cells]
    x = X[:, :1] + np.einsum("mij,maj->mai", F2, X - X[:, :1])
    field = mjed.make_force_field(
        mjed.TetMesh(X.reshape(-1, 3), np.arange(4 * m).reshape(m, 4)), model
    )
    return np.asarray(field.evaluate(x.reshape(-1, 3), want=Want.ENERGY).energy) / split.V0


def _forces(split, P):
    fe = -split.V0[:, None, None] * np.einsum("mkj,maj->mak", P, split.D)
    return assemble(split.cells, split.n, fe, None)[0]


def _f_engine(model, points, split, h, central):
    W0 = _energy_density(model, points, split, split.F)
    P = np.empty_like(split.F)
    for k in range(3):
        for j in range(3):
            E = np.zeros((3, 3))
            E[k, j] = h
            plus = _energy_density(model, points, split, split.F + E)
            if central:
                minus = _energy_density(model, points, split, split.F - E)
                P[:, k, j] = (plus - minus) / (2 * h)
            else:
                P[:, k, j] = (plus - W0) / h
    return _forces(split, P)


def _e_engine(model, points, split, h):
    """S by forward differences in the Voigt strain (engineering shear), F moved so that
    C = F^T F moves by 2 h e_A exactly (F' = R sqrt(C + 2 h e_A), R the polar rotation).
    """
    W0 = _energy_density(model, points, split, split.F)
    C = np.einsum("mki,mkj->mij", split.F, split.F)
    U = _sqrt(C)
    R = split.F @ np.linalg.inv(U)
    S = np.zeros_like(C)
    for i, j in VOIGT:
        e = np.zeros((3, 3))
        e[i, j] += 0.5
        e[j, i] += 0.5
        plus = _energy_density(model, points, split, R @ _sqrt(C + 2 * h * e))
        S[:, i, j] = S[:, j, i] = (plus - W0) / h
    return _forces(split, split.F @ S)


def _sqrt(C):
    w, V = np.linalg.eigh(C)
    return np.einsum("mij,mj,mkj->mik", V, np.sqrt(w), V)


@pytest.mark.parametrize(
    "material, h, central",
    [("Ogden", 1e-6, False), ("MooneyRivlin", 3e-5, False), ("Gent", 2e-3, True)],
)
def test_a_stress_by_differences_of_w_in_f_is_fitted_with_its_step(material, h, central):
    model, points, x, split, f_o, K_o, s = _case(material, 3)
    f = _f_engine(model, points, split, h, central)
    fit = fit_energy_differences(model, split, points, f - f_o)
    assert fit is not None, material
    assert fit.scheme == ("central" if central else "forward"), fit
    assert fit.variable == "each component of F", fit
    assert abs(fit.step / h - 1) < 2e-2 and fit.explained > 0.99, fit


def test_a_stress_by_differences_of_w_in_the_strain_is_told_from_differences_in_f():
    model, points, x, split, f_o, K_o, s = _case("Yeoh", 5)
    h = 1e-5
    fit = fit_energy_differences(model, split, points, _e_engine(model, points, split, h) - f_o)
    assert fit is not None and fit.scheme == "forward", fit
    assert "Green strain" in fit.variable and "engineering" in fit.variable, fit
    assert abs(fit.step / h - 1) < 2e-2, fit


def test_a_stress_off_by_a_factor_is_not_a_difference_quotient():
    model, points, x, split, f_o, K_o, s = _case("Gent", 4)
    assert fit_energy_differences(model, split, points, 1e-6 * f_o) is None


def test_a_spectral_stress_by_differences_of_w_in_the_principal_stretches_is_named():
    """S_a = (1/lambda_a) (W(lambda + h e_a) - W(lambda)) / h, S = sum_a S_a N_a N_a^T, each
    cell moved to U = N diag(lambda + h e_a) N^T (W depends on C alone).
    """
    model, points, x, split, f_o, K_o, s = _case("NeoHookean", 6)
    h = 1e-5
    C = np.einsum("mki,mkj->mij", split.F, split.F)
    w, N = np.linalg.eigh(C)
    lam = np.sqrt(w)
    W0 = _energy_density(model, points, split, split.F)
    S = np.zeros_like(C)
    for a in range(3):
        moved = lam.copy()
        moved[:, a] += h
        U = np.einsum("mij,mj,mkj->mik", N, moved, N)
        dW = (_energy_density(model, points, split, U) - W0) / h
        S += (dW / lam[:, a])[:, None, None] * np.einsum("mi,mj->mij", N[:, :, a], N[:, :, a])
    fit = fit_energy_differences(model, split, points, _forces(split, split.F @ S) - f_o)
    assert fit is not None and fit.scheme == "forward", fit
    assert "principal stretch" in fit.variable, fit
    assert abs(fit.step / h - 1) < 2e-2, fit
