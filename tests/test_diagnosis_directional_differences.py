"""The elasticity tensor applied to each node direction by differences of the stress along it
(conformance.diagnosis.directional_differences): the mistaken engine is built here from the
stress alone (MJED's S at C + 2 h H per cell and direction), the way an edge-based engine's
``applyElasticity`` written by differences does it; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.directional_differences import directional_findings
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.routine_inputs import piola_at


def _second_piola(model, points, split, C):
    """(m, 3, 3) S at right Cauchy-Green tensors C (m, 3, 3), through F = sqrt(C)."""
    w, V = np.linalg.eigh(C)
    U = np.einsum("mij,mj,mkj->mik", V, np.sqrt(w), V)
    P, _ = piola_at(model, points, split, U, stiffness=False)
    return np.linalg.solve(U, P)


def _difference_engine(model, points, split, h, central=False, mirrored=False):
    """K of an engine whose material part is (S(C + 2 h H) - S(C)) / h along each H_bl, or
    (``central``) (S(C + 2 h H) - S(C - 2 h H)) / (2 h); ``mirrored``: each cell's blocks of
    local pairs a > b written as the transposes of those of a < b (an edge-based engine).
    """
    F, D, V0 = split.F, split.D, split.V0
    C = np.swapaxes(F, 1, 2) @ F
    S = _second_piola(model, points, split, C)
    m = len(V0)
    Ke = np.einsum("m,mbI,mIJ,maJ,kl->makbl", V0, D, S, D, np.eye(3))  # geometric part
    for b in range(4):
        for ll in range(3):
            FtdF = np.einsum("mi,mj->mij", F[:, ll, :], D[:, b, :])
            H = 0.5 * (FtdF + np.swapaxes(FtdF, 1, 2))
            if central:
                minus = _second_piola(model, points, split, C - 2 * h * H)
                dS = (_second_piola(model, points, split, C + 2 * h * H) - minus) / (2 * h)
            else:
                dS = (_second_piola(model, points, split, C + 2 * h * H) - S) / h
            Ke[:, :, :, b, ll] += np.einsum("m,mkI,mIJ,maJ->mak", V0, F, dS, D)
    if mirrored:
        a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
        Ke = np.where((a > b)[None, :, None, :, None], Ke.transpose(0, 3, 4, 1, 2), Ke)
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]


@pytest.mark.parametrize("material, h", [("Yeoh", 1e-6), ("MooneyRivlin", 1e-5)])
def test_forward_differences_along_each_direction_are_fitted_with_their_step(material, h):
    model = default_material(material)
    points, cells = box_mesh(2, jitter=0.2, seed=7)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    x = x + 0.02 * np.random.default_rng(7).standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    K = _difference_engine(model, points, split, h)
    found = directional_findings(model, split, points, (K - sp.csr_matrix(K_o)).tocsr(), K_o)
    assert found, "not fitted"
    assembly, fit = found[0]
    assert assembly == "every" and fit.scheme == "forward", found
    assert abs(fit.step / h - 1) < 1e-2 and fit.explained > 0.99, fit


def test_a_tangent_part_scaled_is_not_a_directional_difference():
    model = default_material("Yeoh")
    points, cells = box_mesh(2, jitter=0.2, seed=8)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    K = sp.csr_matrix(K_o) * (1 + 1e-6) + 1e-6 * sp.diags(sp.csr_matrix(K_o).diagonal())
    assert directional_findings(model, split, points, (K - K_o).tocsr(), K_o) == []


def test_central_differences_in_an_edge_based_engine_are_fitted_with_their_step():
    model = default_material("ArrudaBoyce")
    points, cells = box_mesh(2, jitter=0.2, seed=9)
    x = points @ np.diag([1.2, 0.92, 0.9]).T
    x = x + 0.02 * np.random.default_rng(9).standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    K = _difference_engine(model, points, split, 5e-4, central=True, mirrored=True)
    found = directional_findings(model, split, points, (K - sp.csr_matrix(K_o)).tocsr(), K_o)
    assert found, "not fitted"
    assembly, fit = found[0]
    assert assembly == "upper" and fit.scheme == "central", found
    assert abs(fit.step / 5e-4 - 1) < 2e-2 and fit.explained > 0.99, fit
