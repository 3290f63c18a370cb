"""A first elasticity tensor by central differences of P in each component of F
(conformance.diagnosis.central_differences): the mistaken engine differences MJED's first Piola
stress per cell with its own step and assembles its own matrices; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.central_differences import central_piola_fit
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.routine_inputs import piola_at


def _case(material, seed):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    x = x + 0.02 * np.random.default_rng(seed).standard_normal(points.shape)
    model = default_material(material)
    return model, points, x, *mjed_split(model, points, cells, x)


def _central_engine(model, points, split, h):
    m = split.F.shape[0]
    A = np.empty((m, 3, 3, 3, 3))
    for ll in range(3):
        for L in range(3):
            E = np.zeros((3, 3))
            E[ll, L] = h
            plus = piola_at(model, points, split, split.F + E, stiffness=False)[0]
            minus = piola_at(model, points, split, split.F - E, stiffness=False)[0]
            A[:, :, :, ll, L] = (plus - minus) / (2 * h)
    Ke = np.einsum("m,maI,mkIlL,mbL->makbl", split.V0, split.D, A, split.D)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


@pytest.mark.parametrize("material, h", [("Gent", 1e-3), ("Demiray", 3e-3)])
def test_central_differences_of_p_in_f_are_fitted_with_their_step(material, h):
    model, points, x, split, f_o, K_o, s = _case(material, 3)
    K = _central_engine(model, points, split, h)
    fit = central_piola_fit(model, split, points, (K - sp.csr_matrix(K_o)).tocsr(), K_o)
    assert fit is not None and fit.scheme == "central", fit
    assert abs(fit.step / h - 1) < 1e-2 and fit.explained > 0.99, fit


def test_a_scaled_tangent_is_not_central_differences():
    model, points, x, split, f_o, K_o, s = _case("Gent", 4)
    K = sp.csr_matrix(K_o) * (1 + 1e-6)
    assert central_piola_fit(model, split, points, (K - K_o).tocsr(), K_o) is None
